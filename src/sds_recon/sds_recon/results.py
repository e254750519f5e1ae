"""A run's result files (`sds process`, `sds export`) and `load_results` for notebooks.

One CSV per table, comma-separated, a header row of column names, one row per frame and laser
(spots, points), per line sample (line), per frame (fits) or per reading (imu, tof, and the
camera's own IMU, camera_imu);
`columns.json` describes every column; `analysis.json` holds the sloshing estimates. The names
and units are the public interface (docs/results.md) and stay stable.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.csv as pa_csv
from numpy.typing import ArrayLike
from sds_model.errors import InputError

FLAGS_DOC = ("bit flags: 1 lost, 2 saturated, 4 reflection suspected, 8 off its image path, "
             "16 replaced by the Hampel filter (its prediction, no measurement), "
             "64 ambiguous (its blob as likely another diode's: lost)")
COLUMNS: dict[str, dict[str, str]] = {
    "spots": {
        "frame": "frame index, from 0",
        "t_s": "time since the first frame [s]",
        "laser_id": "diode id (rig file)",
        "x_px": "Hampel-filtered spot centre, image column, full frame [px]",
        "y_px": "Hampel-filtered spot centre, image row, full frame [px]",
        "x_raw_px": "spot centre before the Hampel filter, column [px]",
        "y_raw_px": "spot centre before the Hampel filter, row [px]",
        "sigma_px": "one-sigma uncertainty of the centre [px]",
        "intensity": "peak intensity of the spot [0-255]",
        "valid": "1 measured in this frame, 0 lost or replaced by the Hampel filter",
        "flags": FLAGS_DOC,
    },
    "points": {
        "frame": "frame index, from 0",
        "t_s": "time since the first frame [s]",
        "laser_id": "diode id, or 65535 for the line laser",
        "X_mm": "surface point, world frame of the rig file [mm]",
        "Y_mm": "surface point, world frame [mm]",
        "Z_mm": "surface height above the flat fill level [mm]",
        "sigma_Z_mm": "one-sigma height uncertainty from the pixel uncertainty [mm]",
        "miss_mm": "distance between camera ray and beam (Eq. 9); empty for the line [mm]",
        "rejected": "1 left out of the frame's fits as not on the surface (a ray missing its "
                    "beam or a height off the modal surface by > 4 of its sigma), else 0",
    },
    "line": {
        "frame": "frame index, from 0",
        "t_s": "time since the first frame [s]",
        "x_px": "line centre, image column, full frame [px]",
        "y_px": "image row of the sample [px]",
        "sigma_px": "one-sigma uncertainty of the centre [px]",
        "intensity": "peak intensity [0-255]",
        "flags": "bit flags: 1 interpolated over a gap, 2 saturated, 4 low signal",
    },
    "fits": {
        "frame": "frame index, from 0",
        "t_s": "time since the first frame [s]",
        "p00_mm": "plane g = p00 + p10 X + p01 Y (seed Eq. 12): height at the axis [mm]",
        "p10": "plane slope along X [mm/mm]",
        "p01": "plane slope along Y [mm/mm]",
        "tilt_x_deg": "tilt -atan(p10) [deg]",
        "tilt_y_deg": "tilt -atan(p01) [deg]",
        "r_squared": "coefficient of determination of the plane",
        "rmse_mm": "root mean square residual of the plane [mm]",
        "sse_mm2": "sum of squared residuals of the plane [mm²]",
        "point_count": "laser-spot points in the fit (after the rejected ones)",
        "rejected_count": "laser-spot points left out as not on the surface (points.rejected)",
        "<mode>_mm": "modal amplitude (mean level, lateral_n_cos/sin, axisymmetric_n) [mm]",
    },
    "imu": {
        "t_s": "time since the first frame [s]",
        "ax_m_s2": "acceleration along X (the excitation) [m/s²]",
        "ay_m_s2": "acceleration along Y [m/s²]",
        "az_m_s2": "acceleration along Z [m/s²]",
    },
    "tof": {
        "t_s": "time since the first frame [s]",
        "range_mm": "time-of-flight distance to the liquid [mm]",
    },
    "camera_imu": {
        "t_s": "time on the video's clock, 0 at the first frame [s]",
        "ax_m_s2": "camera accelerometer, optical frame x (image right) [m/s²]; empty on a "
                   "gyroscope row",
        "ay_m_s2": "camera accelerometer, optical y (image down) [m/s²]",
        "az_m_s2": "camera accelerometer, optical z (viewing direction) [m/s²]",
        "gx_rad_s": "camera gyroscope about optical x [rad/s]; empty on an accelerometer row",
        "gy_rad_s": "camera gyroscope about optical y [rad/s]",
        "gz_rad_s": "camera gyroscope about optical z [rad/s]",
    },
}
"""Every table's columns and what they mean (written as columns.json)."""


SAMPLE_TIME_COLUMN = {
    "t_sample_s": "time the point's image row was exposed, since the first frame [s]: t_s plus "
                  "the row's delay under the camera's rolling shutter (its camera file's "
                  "readout_s; written only for a rolling shutter)"}
"""The points table's last column when the camera reads its rows over a time."""


INTEGER_COLUMNS = frozenset({"frame", "laser_id", "valid", "flags", "point_count", "rejected",
                             "rejected_count"})
"""Columns of whole numbers; every other column is a float (NaN written as an empty cell)."""
TABLE_FILES = (*(f"{table}.csv" for table in COLUMNS), "columns.json")
"""The files of a results folder's tables (the analysis adds its report)."""
BATCH_ROWS = 65536
"""Rows a table buffers before they are formatted and written in one go."""


class _TableFile:
    """One table's CSV file: a header row, then rows written in batches by pyarrow's CSV
    writer (shortest round-trip floats, NaN as an empty cell)."""

    def __init__(self, path: Path, header: list[str]) -> None:
        self.header = header
        self._stream = path.open("wb")
        self._stream.write((",".join(header) + "\n").encode())
        self._columns: list[list[np.ndarray]] = [[] for _ in header]
        self._rows = 0

    def append(self, columns: list[np.ndarray]) -> None:
        """Columns of equal length, in the header's order."""
        for chunks, column in zip(self._columns, columns, strict=True):
            chunks.append(column)
        self._rows += len(columns[0])
        if self._rows >= BATCH_ROWS:
            self.flush()

    def flush(self) -> None:
        """Write the buffered rows."""
        if not self._rows:
            return
        arrays = []
        for name, chunks in zip(self.header, self._columns, strict=True):
            if name in INTEGER_COLUMNS:
                arrays.append(pa.array(np.concatenate(chunks).astype(np.int64)))
            else:
                values = np.concatenate(chunks).astype(np.float64)
                arrays.append(pa.array(values, mask=~np.isfinite(values)))
        table = pa.Table.from_arrays(arrays, names=self.header)
        pa_csv.write_csv(table, self._stream, pa_csv.WriteOptions(include_header=False,
                                                                  quoting_style="none"))
        self._columns = [[] for _ in self.header]
        self._rows = 0

    def close(self) -> None:
        """Write what is buffered and close the file."""
        self.flush()
        self._stream.close()


def refuse_results(directory: Path) -> None:
    """FileExistsError when `directory` holds result files already."""
    earlier = [name for name in TABLE_FILES if (directory / name).exists()]
    if earlier:
        raise InputError(f"{directory} holds results already ({earlier[0]}, …): "
                              "another folder, or --overwrite")


class ResultsWriter:
    """Streams rows into the tables' CSV files (opened at their first row, written in batches);
    a folder that holds results already is refused unless `overwrite`."""

    def __init__(self, directory: str | Path, overwrite: bool = False) -> None:
        self.directory = Path(directory)
        if not overwrite:
            refuse_results(self.directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self._tables: dict[str, _TableFile] = {}
        self._modal_names: tuple[str, ...] | None = None
        self._timed_points = False

    def time_points(self) -> None:
        """Give the points table its SAMPLE_TIME_COLUMN (before its first row): each row then
        ends with its sample time."""
        if "points" in self._tables:
            raise ValueError("time_points() after the first points row")
        self._timed_points = True

    def _columns(self, table: str) -> dict[str, str]:
        """A table's columns and their meaning, as written."""
        if table == "points" and self._timed_points:
            return {**COLUMNS[table], **SAMPLE_TIME_COLUMN}
        return COLUMNS[table]

    def _table(self, table: str, header: list[str]) -> _TableFile:
        if table not in self._tables:
            self._tables[table] = _TableFile(self.directory / f"{table}.csv", header)
        return self._tables[table]

    def add_columns(self, table: str, columns: list[ArrayLike]) -> None:
        """Rows of a table as columns, in the order of COLUMNS[table]: arrays of one length
        (none, e.g. a frame without line samples, adds no row) and single values that every
        row repeats (the frame, its time)."""
        arrays = [np.atleast_1d(np.asarray(c)) for c in columns]
        lengths = {len(a) for a in arrays if len(a) != 1}
        if len(lengths) > 1:
            raise ValueError(f"{table}: columns of different lengths {sorted(lengths)}")
        length = lengths.pop() if lengths else 1
        file = self._table(table, list(self._columns(table)))
        if length:
            file.append([np.broadcast_to(a, (length,)) for a in arrays])

    def add(self, table: str, rows: list[tuple[Any, ...]]) -> None:
        """Rows of a table (values in the order of COLUMNS[table]; None or NaN: empty)."""
        if rows:
            self.add_columns(table, [np.array(c, dtype=float) for c in zip(*rows, strict=True)])

    def add_fit(self, row: tuple[Any, ...], modal_names: tuple[str, ...],
                amplitudes: list[float]) -> None:
        """One frame's fit; the modal columns are fixed by the first frame that has them."""
        if self._modal_names is None and modal_names:
            self._modal_names = modal_names
        names = self._modal_names or ()
        header = [c for c in COLUMNS["fits"] if c != "<mode>_mm"] + [f"{n}_mm" for n in names]
        values = dict(zip(modal_names, amplitudes, strict=True))
        cells = [*row, *(values.get(n, np.nan) for n in names)]
        table = self._table("fits", header)
        table.append([np.array([c], dtype=float) for c in cells[:len(table.header)]])

    def close(self, analysis: dict[str, Any] | None = None) -> list[Path]:
        """Close the tables, write columns.json (and analysis.json); the files written."""
        for table in self._tables.values():
            table.close()
        written = [self.directory / f"{table}.csv" for table in self._tables]
        described = {table: self._columns(table) for table in self._tables}
        (self.directory / "columns.json").write_text(json.dumps(described, indent=2,
                                                                ensure_ascii=False) + "\n")
        written.append(self.directory / "columns.json")
        if analysis is not None:
            (self.directory / "analysis.json").write_text(json.dumps(analysis, indent=2) + "\n")
            written.append(self.directory / "analysis.json")
        return written


@dataclass(frozen=True)
class Results:
    """A results folder: each table as a numpy structured array (None if absent), the analysis."""

    spots: np.ndarray | None = None
    points: np.ndarray | None = None
    line: np.ndarray | None = None
    fits: np.ndarray | None = None
    imu: np.ndarray | None = None
    tof: np.ndarray | None = None
    camera_imu: np.ndarray | None = None
    analysis: dict[str, Any] | None = None
    columns: dict[str, Any] = field(default_factory=dict)


def _read_table(path: Path) -> np.ndarray | None:
    """A table as a structured array (floats, with NaN for empty cells; ids as integers)."""
    if not path.is_file():
        return None
    with path.open(newline="") as stream:
        rows = list(csv.reader(stream))
    header, body = rows[0], rows[1:]
    dtype = [(name, np.int64 if name in INTEGER_COLUMNS else np.float64) for name in header]
    table = np.zeros(len(body), dtype=dtype)
    for index, name in enumerate(header):
        values = [row[index] for row in body]
        if name in INTEGER_COLUMNS:
            table[name] = [int(v) for v in values]
        else:
            table[name] = [float(v) if v else np.nan for v in values]
    return table


def load_results(directory: str | Path) -> Results:
    """Read a folder written by `sds process` or `sds export` (tables as numpy arrays; for
    pandas: `pandas.read_csv(folder / "points.csv")`)."""
    directory = Path(directory)
    if not directory.is_dir():
        raise InputError(f"{directory}: no such results folder")
    tables = {table: _read_table(directory / f"{table}.csv") for table in COLUMNS}
    analysis_path, columns_path = directory / "analysis.json", directory / "columns.json"
    analysis = json.loads(analysis_path.read_text()) if analysis_path.is_file() else None
    columns = json.loads(columns_path.read_text()) if columns_path.is_file() else {}
    return Results(**tables, analysis=analysis, columns=columns)
