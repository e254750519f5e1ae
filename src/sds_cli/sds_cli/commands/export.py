"""`sds export`: a recording of the graph as result files and an analysis report."""

from __future__ import annotations

import argparse
from pathlib import Path

from sds_cli.commands import add_overwrite


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds export`."""
    parser = commands.add_parser(
        "export", help="a recording's spots, points, line, fits, IMU, ToF and analysis as files",
        description="Write the result files of a recording of the graph (see README, "
                    "'Result files').")
    parser.add_argument("recording", type=Path, help="a recording of the graph (MCAP)")
    parser.add_argument("--rig", type=Path,
                        help="the rig file (default: the one the recording carries)")
    parser.add_argument("--out", type=Path, required=True,
                        help="folder for the result files (refused if it holds results)")
    add_overwrite(parser, "replace the results of an earlier export in --out")
    parser.add_argument("--gravity", type=float, help="gravity for the theory [m/s²]")
    parser.set_defaults(run=run, command="export")


def run(args: argparse.Namespace) -> int:
    """Result files and the analysis report of one recording."""
    from sds_workflows.export import export_results

    frames, analysis = export_results(args.recording, args.out, args.rig, args.gravity,
                                      args.overwrite)
    note = analysis.note
    print(f"sds export: {frames} frames of {args.recording} -> {args.out}" + (
        f" ({note})" if note else ""))
    return 0
