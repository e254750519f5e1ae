"""`sds run`: a video or a live camera through the whole graph, then the analysis."""

from __future__ import annotations

import argparse
from pathlib import Path

from sds_cli.commands import (
    CommandError,
    add_lateral_options,
    add_overwrite,
    lateral_input,
    refuse_existing,
)


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds run`."""
    parser = commands.add_parser(
        "run", help="a video or a live camera through the whole graph, then the analysis",
        description="Run the whole chain (config/graphs/drop.yaml + arduino.yaml + view.yaml) "
                    "on a recorded video or a live camera; Ctrl-C stops a live run.")
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--video", help="video file")
    source.add_argument("--camera", help="camera device, e.g. /dev/video0")
    parser.add_argument("--rig", type=Path, required=True, help="the rig file")
    parser.add_argument("--out", type=Path, default=Path("run_output"),
                        help="folder for the recording, Rerun file, results and report")
    parser.add_argument("--port", help="the Arduino's serial port (default: arduino.yaml's)")
    parser.add_argument("--gravity", type=float, help="gravity for the theory [m/s²]")
    add_overwrite(parser, "replace the recording and results of an earlier run in --out")
    add_lateral_options(parser, "a second, lateral camera's video run beside the top one "
                        "(config/graphs/lateral.yaml: recorded, shown), then its check of the "
                        "top surface")
    parser.set_defaults(run=run, command="run")


def run(args: argparse.Namespace) -> int:
    """The run; the graph's exit code when a needed node failed."""
    from sds_bringup.chain import run_chain
    from sds_workflows.demo import run_live

    if args.video is not None and not Path(args.video).is_file():
        # Before the graph: its processes take seconds to start and then fail on the same.
        raise CommandError(f"video file {args.video} does not exist")
    refuse_existing(args.out / "recording.mcap", args.overwrite)
    lateral = lateral_input(args)
    return run_live(args.video or args.camera, args.rig, args.out, args.port, args.gravity,
                    run_chain, args.overwrite, lateral)
