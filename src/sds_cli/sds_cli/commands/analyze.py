"""`sds analyze`: sloshing frequencies, damping ratios, tilts and meniscus, with a report."""

from __future__ import annotations

import argparse
from pathlib import Path

from sds_cli.commands import (
    CommandError,
    add_overwrite,
    existing_file,
    non_negative_float,
    output_folder,
    refuse_existing,
)


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds analyze`."""
    parser = commands.add_parser(
        "analyze", help="sloshing frequencies, damping ratios, tilts and meniscus, with a report",
        description="Analyse a recording: an MCAP with the reconstruction's points, a points CSV "
                    "(frame,t_s,laser_id,X_mm,Y_mm,Z_mm), a time-series CSV (t_s, then one "
                    "column per series, e.g. one spot's pixel position) or an Arduino log "
                    "(serial capture or SD card: the ToF quick estimate). Writes analysis.json, "
                    "report.html and figures.")
    parser.add_argument("recording", type=existing_file,
                        help="MCAP, points CSV, time-series CSV or Arduino log")
    parser.add_argument("--rig", type=existing_file,
                        help="the rig file: container, liquid, gravity for the theory (default: "
                             "an MCAP's own rig; for tables and logs config/rigs/stelium.yaml)")
    parser.add_argument("--out", type=output_folder, default=Path("analysis"),
                        help="folder for analysis.json, report.html and figures")
    parser.add_argument("--start-s", type=float, help="free decay starts here [s]")
    parser.add_argument("--end-s", type=float, help="analysis window ends here [s]")
    parser.add_argument("--forcing-s", type=float,
                        help="the free decay starts this long after the excitation's onset [s]")
    parser.add_argument("--gravity", type=non_negative_float, help="gravity for the theory [m/s²] "
                        "(default: the rig's; 0 for a drop: capillary theory, docs/sloshing.md)")
    parser.add_argument("--expected", action="append", default=[], metavar="MODE=HZ",
                        help="expected frequency of a mode, e.g. lateral_1=1.9 (repeatable)")
    parser.add_argument("--truth", type=existing_file,
                        help="a simulation's truth/run.json: the report gives each error")
    add_overwrite(parser, "replace the report of an earlier analysis in --out")
    parser.set_defaults(run=run, command="analyze")


def expected_frequencies(items: list[str]) -> dict[str, float]:
    """--expected MODE=HZ items as {mode: Hz}."""
    expected = {}
    for item in items:
        name, _, value = item.partition("=")
        try:
            expected[name.strip()] = float(value)
        except ValueError:
            raise CommandError(f"--expected {item!r}: give MODE=HZ, e.g. lateral_1=1.9") from None
    return expected


def run(args: argparse.Namespace) -> int:
    """Analyse, write the report, print the summary."""
    refuse_existing(args.out / "analysis.json", args.overwrite,
                    "exists: the folder holds an analysis already")
    from sds_sloshing.analysis import AnalysisOptions
    from sds_sloshing.report import summary_lines, truth_from_run, write_report
    from sds_sloshing.surface_series import RecordingError
    from sds_workflows.analyze import analyse_recording

    options = AnalysisOptions(args.start_s, args.end_s, args.forcing_s, args.gravity,
                              expected_frequencies(args.expected))
    try:
        analysis = analyse_recording(args.recording, args.rig, options)
    except RecordingError as error:   # data that give no analysis, said as export and run say it
        raise RecordingError(f"NO ANALYSIS: {error}") from error
    truth = truth_from_run(args.truth) if args.truth else None
    files = write_report(analysis, args.out, truth)
    print(f"sds analyze: {analysis.source}, free decay {analysis.window_s[0]:.3f}–"
          f"{analysis.window_s[1]:.3f} s")
    for line in summary_lines(files.results):
        print(f"  {line}")
    print(f"wrote {files.json}, {files.html}")
    return 0
