"""`sds run`: a video or a live camera through the whole graph, then the analysis."""

from __future__ import annotations

import argparse
from pathlib import Path

from sds_cli.commands import (
    CommandError,
    add_lateral_options,
    add_overwrite,
    existing_file,
    lateral_input,
    non_negative_float,
    output_folder,
    refuse_existing,
)


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds run`."""
    parser = commands.add_parser(
        "run", help="a video or a live camera through the whole graph, then the analysis",
        description="Run the whole chain (config/graphs/drop.yaml + arduino.yaml + view.yaml) "
                    "on a recorded video or a live camera; Ctrl-C stops a live run.")
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--video", type=existing_file, help="video file")
    source.add_argument("--camera", help="camera device, e.g. /dev/video0")
    parser.add_argument("--rig", type=existing_file, required=True, help="the rig file")
    parser.add_argument("--out", type=output_folder, default=Path("run_output"),
                        help="folder for the recording, Rerun file, results and report")
    arduino = parser.add_mutually_exclusive_group()
    arduino.add_argument("--port", help="the Arduino's serial port (default: arduino.yaml's); "
                                        "refused if it does not exist")
    arduino.add_argument("--no-arduino", action="store_true",
                         help="run without the Arduino (no accelerometer, no ToF)")
    parser.add_argument("--gravity", type=non_negative_float, help="gravity for the theory [m/s²]")
    add_overwrite(parser, "replace the recording and results of an earlier run in --out")
    add_lateral_options(parser, "a second, lateral camera's video run beside the top one "
                        "(config/graphs/lateral.yaml: recorded, shown), then its check of the "
                        "top surface")
    parser.set_defaults(run=run, command="run")


def run(args: argparse.Namespace) -> int:
    """The run; the graph's exit code when a needed node failed, 2 when a source of data it
    was asked for (the Arduino) gave nothing."""
    from sds_bringup.chain import run_chain
    from sds_record.mcap_files import holds_messages
    from sds_workflows.demo import run_live

    if args.camera is not None and args.camera.startswith("/") and \
            not Path(args.camera).exists():
        raise CommandError(f"camera device {args.camera} does not exist (is it plugged in? "
                           "`v4l2-ctl --list-devices` lists them)")
    port = None if args.no_arduino else args.port or default_arduino_port()
    if port is not None and not Path(port).exists():
        raise CommandError(f"the Arduino's port {port} does not exist: plug it in, name its "
                           "port with --port, or run without it with --no-arduino")
    recording = args.out / "recording.mcap"
    if recording.is_file() and holds_messages(recording):
        refuse_existing(recording, args.overwrite)
    lateral = lateral_input(args)
    return run_live(args.video or args.camera, args.rig, args.out, port, args.gravity,
                    run_chain, args.overwrite, lateral)


def default_arduino_port() -> str:
    """The serial port config/graphs/arduino.yaml gives its bridge."""
    from sds_model.paths import CONFIG
    from sds_ros.graph_file import node_parameters

    return str(node_parameters(CONFIG / "graphs" / "arduino.yaml", "arduino")["port"])
