"""`sds export`: a recording of the graph as result files and an analysis report."""

from __future__ import annotations

import argparse
import sys

from sds_cli.commands import add_overwrite, existing_file, non_negative_float, output_folder


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds export`."""
    parser = commands.add_parser(
        "export", help="a recording's spots, points, line, fits, IMU, ToF and analysis as files",
        description="Write the result files of a recording of the graph (docs/results.md).")
    parser.add_argument("recording", type=existing_file, help="a recording of the graph (MCAP)")
    parser.add_argument("--rig", type=existing_file,
                        help="the rig file (default: the one the recording carries)")
    parser.add_argument("--out", type=output_folder, required=True,
                        help="folder for the result files (refused if it holds results)")
    add_overwrite(parser, "replace the results of an earlier export in --out")
    parser.add_argument("--gravity", type=non_negative_float, help="gravity for the theory [m/s²]")
    parser.set_defaults(run=run, command="export")


def run(args: argparse.Namespace) -> int:
    """Result files and the analysis report of one recording; exit code 2 when the data gave
    no analysis (the result files are written)."""
    from sds_workflows.export import export_results

    frames, analysis = export_results(args.recording, args.out, args.rig, args.gravity,
                                      args.overwrite)
    note = analysis.note
    print(f"sds export: {frames} frames of {args.recording} -> {args.out}" + (
        f" ({note})" if note else ""), file=sys.stdout if analysis.results else sys.stderr)
    if analysis.sigma_check is not None:
        print(f"sds export: spots' σ check: {analysis.sigma_check.line()}")
    return 0 if analysis.results else 2
