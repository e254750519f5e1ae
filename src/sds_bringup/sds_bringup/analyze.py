"""`sds analyze`: frequencies, damping ratios, tilts and meniscus of a recording, and a report."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from sds_arduino.protocol import read_log, unwrap_time_s
from sds_recon.rig import RigError, load_rig
from sds_recon.sloshing.analysis import AnalysisOptions, analyze, analyze_table
from sds_recon.sloshing.estimators import DecayError
from sds_recon.sloshing.gravity import gravity_regime
from sds_recon.sloshing.recording import (
    RecordingError,
    read_mcap,
    read_mcap_accelerations,
    read_points_csv,
    read_series_csv,
)
from sds_recon.sloshing.report import summary_lines, truth_from_run, write_report

from sds_bringup.paths import CONFIG

ARDUINO_LOG_SUFFIXES = (".txt", ".log")


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds analyze`."""
    parser = commands.add_parser(
        "analyze", help="sloshing frequencies, damping ratios, tilts and meniscus, with a report",
        description="Analyse a recording: an MCAP with the reconstruction's points, a points CSV "
                    "(frame,t_s,laser_id,X_mm,Y_mm,Z_mm), a time-series CSV (t_s, then one "
                    "column per series, e.g. one spot's pixel position) or an Arduino log "
                    "(serial capture or SD card: the ToF quick estimate). Writes analysis.json, "
                    "report.html and figures.")
    parser.add_argument("recording", type=Path,
                        help="MCAP, points CSV, time-series CSV or Arduino log")
    parser.add_argument("--rig", type=Path, default=CONFIG / "rigs" / "stelium.yaml",
                        help="the rig file (container, liquid, gravity for the theory)")
    parser.add_argument("--out", type=Path, default=Path("analysis"),
                        help="folder for analysis.json, report.html and figures")
    parser.add_argument("--start-s", type=float, help="free decay starts here [s]")
    parser.add_argument("--end-s", type=float, help="analysis window ends here [s]")
    parser.add_argument("--forcing-s", type=float,
                        help="the free decay starts this long after the excitation's onset [s]")
    parser.add_argument("--gravity", type=float, help="gravity for the theory [m/s²] "
                        "(default: the rig's; 0 for a drop: capillary theory, see README)")
    parser.add_argument("--expected", action="append", default=[], metavar="MODE=HZ",
                        help="expected frequency of a mode, e.g. lateral_1=1.9 (repeatable)")
    parser.add_argument("--truth", type=Path,
                        help="a simulation's truth/run.json: the report gives each error")
    parser.set_defaults(run=run)


def _options(args: argparse.Namespace) -> AnalysisOptions:
    expected = {}
    for item in args.expected:
        name, _, value = item.partition("=")
        try:
            expected[name.strip()] = float(value)
        except ValueError:
            raise ValueError(f"--expected {item!r}: give MODE=HZ, e.g. lateral_1=1.9") from None
    return AnalysisOptions(args.start_s, args.end_s, args.forcing_s, args.gravity, expected)


def _analysis(args: argparse.Namespace, options: AnalysisOptions):
    rig = load_rig(args.rig)
    path: Path = args.recording
    if not path.is_file():
        raise RecordingError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".mcap":
        return analyze(read_mcap(path), rig, with_gravity_regime(path, options))
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


def with_gravity_regime(recording: Path, options: AnalysisOptions) -> AnalysisOptions:
    """The options, with microgravity where no gravity was given and a recorded accelerometer
    (the Arduino's or the camera's) shows a free fall; says so on the console."""
    if options.gravity_m_s2 is not None:
        return options
    gravity, note = gravity_regime(read_mcap_accelerations(recording))
    if note:
        print(f"sds: {note}")
    return replace(options, gravity_m_s2=gravity)


def _header(path: Path) -> str:
    """A table's header row: its first line that is neither empty nor a comment."""
    with path.open(errors="replace") as stream:
        return next((line for line in stream if line.strip() and not line.startswith("#")), "")


def run(args: argparse.Namespace) -> int:
    """Analyse, write the report, print the summary; one-line errors with exit code 2."""
    try:
        options = _options(args)
        analysis = _analysis(args, options)
        truth = truth_from_run(args.truth) if args.truth else None
    except (RecordingError, RigError, DecayError, ValueError, OSError, KeyError) as error:
        print(f"sds analyze: {error}", file=sys.stderr)
        return 2
    files = write_report(analysis, args.out, truth)
    print(f"sds analyze: {analysis.source}, free decay {analysis.window_s[0]:.3f}–"
          f"{analysis.window_s[1]:.3f} s")
    for line in summary_lines(files.results):
        print(f"  {line}")
    print(f"wrote {files.json}, {files.html}")
    return 0
