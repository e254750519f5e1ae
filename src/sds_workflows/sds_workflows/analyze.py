"""Analysis of a recording, whatever its kind (MCAP, points or time-series CSV, Arduino log)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from sds_arduino.protocol import read_log, unwrap_time_s
from sds_model.paths import CONFIG
from sds_model.rig import load_rig
from sds_record.recorded_series import (
    read_accelerations,
    read_surface_series,
    recording_rig,
)
from sds_sloshing.analysis import (
    AnalysisOptions,
    SloshingAnalysis,
    analyze,
    analyze_table,
    with_gravity_regime,
)
from sds_sloshing.surface_series import RecordingError, read_points_csv, read_series_csv

ARDUINO_LOG_SUFFIXES = (".txt", ".log")
DEFAULT_RIG = CONFIG / "rigs" / "stelium.yaml"
"""The rig of a table or log analysed without --rig: the seed's."""


def analyse_recording(path: Path, rig_file: Path | None, options: AnalysisOptions
                      ) -> SloshingAnalysis:
    """The analysis of an MCAP (with its own rig unless `rig_file` is given), a points or
    time-series CSV, or an Arduino log (ToF) (with `rig_file`, default the seed's rig)."""
    if not path.is_file():
        raise RecordingError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".mcap":
        if options.gravity_m_s2 is None:   # only then are the accelerometers read
            options, note = with_gravity_regime(options, read_accelerations(path))
            if note:
                print(f"sds: {note}")
        return analyze(read_surface_series(path), recording_rig(path, rig_file), options)
    rig = load_rig(rig_file or DEFAULT_RIG)
    if suffix in ARDUINO_LOG_SUFFIXES:
        records, rejected = read_log(path)
        tof = [r for r in records if r.kind == "TOF" and r.values[1] == 0]
        if len(tof) < 16:
            raise RecordingError(f"{path}: {len(tof)} valid ToF records ({rejected} lines "
                                 "rejected); 16 or more needed")
        time_s = unwrap_time_s([r.t_us for r in tof])
        ranges = np.array([r.values[0] for r in tof], dtype=float)
        return analyze_table(str(path), time_s, {"tof_range_mm": ranges}, rig, options, "mm",
                             tof=True)
    if "laser_id" in _header(path):
        return analyze(read_points_csv(path), rig, options)
    time_s, series = read_series_csv(path)
    return analyze_table(str(path), time_s, series, rig, options)


def _header(path: Path) -> str:
    """A table's header row: its first line that is neither empty nor a comment."""
    with path.open(errors="replace") as stream:
        return next((line for line in stream if line.strip() and not line.startswith("#")), "")
