"""What the analysis reads: surface points per frame and laser, line points, ToF ranges.

Sources: a points CSV with the columns `frame, t_s, laser_id, X_mm, Y_mm, Z_mm` (more columns
are ignored; laser_id 65535 is the line), a time-series CSV, or the point clouds of an MCAP
recording (read by `sds_record.recorded_series`, grouped here).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from sds_model.errors import InputError
from sds_recon.reconstruction import LINE_LASER_ID

POINTS_COLUMNS = ("frame", "t_s", "laser_id", "X_mm", "Y_mm", "Z_mm")


class RecordingError(InputError):
    """A recording or table the analysis cannot read; the message names the problem."""


@dataclass(frozen=True)
class SurfaceSeries:
    """Surface points per frame and diode [mm] (NaN = not measured), line points, ToF ranges."""

    time_s: np.ndarray              # (F,) frame times
    laser_ids: np.ndarray           # (L,)
    points_mm: np.ndarray           # (F, L, 3)
    line_time_s: np.ndarray = field(default_factory=lambda: np.empty(0))  # (M,)
    line_points_mm: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))  # (M, 3)
    tof_time_s: np.ndarray = field(default_factory=lambda: np.empty(0))
    tof_range_mm: np.ndarray = field(default_factory=lambda: np.empty(0))
    source: str = ""


def surface_series_from_rows(time_s: np.ndarray, laser_ids: np.ndarray, points_mm: np.ndarray,
                        source: str = "", tof: tuple[np.ndarray, np.ndarray] | None = None,
                        ) -> SurfaceSeries:
    """Group rows of (time [s], laser id, X Y Z [mm]) into frames; the line's rows stay a list."""
    time_s, laser_ids = np.asarray(time_s, dtype=float), np.asarray(laser_ids, dtype=int)
    points_mm = np.asarray(points_mm, dtype=float).reshape(-1, 3)
    line = laser_ids == LINE_LASER_ID
    spot_times, frame_of = np.unique(time_s[~line], return_inverse=True)
    ids, laser_of = np.unique(laser_ids[~line], return_inverse=True)
    if len(spot_times) == 0:
        raise RecordingError(f"{source}: no laser spot points")
    table = np.full((len(spot_times), len(ids), 3), np.nan)
    table[frame_of, laser_of] = points_mm[~line]
    tof_time, tof_range = tof if tof is not None else (np.empty(0), np.empty(0))
    return SurfaceSeries(spot_times, ids, table, time_s[line], points_mm[line],
                            np.asarray(tof_time, dtype=float), np.asarray(tof_range, dtype=float),
                            source)


def read_points_csv(path: str | Path) -> SurfaceSeries:
    """A points CSV (`sds export` layout; lines starting with # are comments), without the
    points marked rejected."""
    path = Path(path)
    with path.open(newline="") as stream:
        reader = csv.DictReader(line for line in stream if not line.startswith("#"))
        missing = [c for c in POINTS_COLUMNS if c not in (reader.fieldnames or ())]
        if missing:
            raise RecordingError(f"{path}: missing columns {', '.join(missing)}")
        # points the run left out of its fits (column `rejected`) stay out of the analysis
        rows = [r for r in reader if r.get("rejected", "0") != "1"]
    try:
        times = np.array([float(r["t_s"]) for r in rows])
        ids = np.array([int(r["laser_id"]) for r in rows])
        points = np.array([[float(r["X_mm"]), float(r["Y_mm"]), float(r["Z_mm"])] for r in rows])
    except ValueError as error:
        raise RecordingError(f"{path}: {error}") from None
    return surface_series_from_rows(times, ids, points, str(path))


def read_series_csv(path: str | Path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A time-series table: first column time [s], one column per series (e.g. one spot's px)."""
    path = Path(path)
    with path.open(newline="") as stream:
        rows = [r for r in csv.reader(line for line in stream if not line.startswith("#")) if r]
    if len(rows) < 2 or len(rows[0]) < 2:
        raise RecordingError(f"{path}: need a header and a time column plus one or more series")
    try:
        table = np.array([[float(v) if v.strip() else np.nan for v in r] for r in rows[1:]])
    except ValueError as error:
        raise RecordingError(f"{path}: {error}") from None
    names = [name.strip() for name in rows[0]]
    return table[:, 0], {name: table[:, k] for k, name in enumerate(names[1:], start=1)}
