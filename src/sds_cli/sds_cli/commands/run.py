"""`sds run`: a video or a live camera through the whole graph, then the analysis."""

from __future__ import annotations

import argparse
from pathlib import Path

from sds_cli.commands import CommandError, add_overwrite, refuse_existing


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
    side = parser.add_argument_group(
        "side camera", "a second, lateral camera's video run beside the top one "
        "(config/graphs/lateral.yaml: recorded, shown), then its check of the top surface")
    side.add_argument("--lateral", type=Path, metavar="VIDEO", help="the side camera's video")
    side.add_argument("--lateral-view", type=Path, metavar="FILE",
                      help="its view file (config/lateral/*.yaml)")
    side.add_argument("--lateral-board", type=Path, nargs="+", metavar="IMAGE",
                      help="its images of the checkerboard at the view file's placements "
                           "(one each, in order)")
    side.add_argument("--led-roi", type=int, nargs=4, metavar=("X", "Y", "W", "H"),
                      help="the sync LED's region in the top video (links the clocks)")
    side.add_argument("--arduino-log", type=Path, metavar="LOG",
                      help="the Arduino's log of the drop: a second clock link")
    parser.set_defaults(run=run, command="run")


def run(args: argparse.Namespace) -> int:
    """The run; the graph's exit code when a needed node failed."""
    from sds_bringup.chain import run_chain
    from sds_workflows.demo import run_live
    from sds_workflows.lateral import LateralInput

    refuse_existing(args.out / "recording.mcap", args.overwrite)
    lateral = None
    if args.lateral is not None:
        if args.lateral_view is None or args.lateral_board is None:
            raise CommandError("--lateral needs --lateral-view and --lateral-board")
        if args.led_roi is None and args.arduino_log is None:
            raise CommandError("--lateral needs --led-roi (the LED in the top video) or "
                               "--arduino-log to link the side camera's clock")
        lateral = LateralInput(args.lateral, args.lateral_view, tuple(args.lateral_board),
                               tuple(args.led_roi) if args.led_roi else None, args.arduino_log)
    return run_live(args.video or args.camera, args.rig, args.out, args.port, args.gravity,
                    run_chain, args.overwrite, lateral)
