"""`sds simulate`: render a scenario as the rig's camera and Arduino would record it."""

from __future__ import annotations

import argparse
from pathlib import Path

from sds_cli.commands import (
    add_overwrite,
    existing_file,
    output_folder,
    positive_float,
    refuse_existing,
)


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds simulate`."""
    parser = commands.add_parser(
        "simulate", help="render a simulated run: video, Arduino streams, ground truth",
        description="Render a scenario (config/scenarios/*.yaml) as the rig's camera and Arduino "
                    "would record it, with the exact truth beside it (format: sds_sim.simulate).")
    parser.add_argument("scenario", type=existing_file,
                        help="scenario file (config/scenarios/*.yaml)")
    parser.add_argument("--out", type=output_folder, default=Path("simulation"),
                        help="folder for the video, the Arduino streams and the truth "
                             "(default: simulation)")
    parser.add_argument("--seconds", type=positive_float,
                        help="override the scenario's duration [s]")
    parser.add_argument("--scale", type=positive_float, help="image scale, e.g. 0.25 for 960x540")
    parser.add_argument("--seed", type=int, help="override the scenario's random seed")
    parser.add_argument("--codec", choices=["h264", "lossless", "png"], default="h264",
                        help="h264 as the camera writes (default), lossless H.264, or PNG "
                             "images")
    add_overwrite(parser, "replace an earlier simulation in --out")
    parser.set_defaults(run=run, command="simulate")


def run(args: argparse.Namespace) -> int:
    """Simulate and list the files written."""
    import time

    from sds_sim.scenario import load_scenario
    from sds_sim.simulate import simulate

    overrides = {key: value for key, value in (("duration_s", args.seconds),
                                               ("scale", args.scale), ("seed", args.seed))
                 if value is not None}
    scenario = load_scenario(args.scenario, overrides)
    refuse_existing(args.out / "truth" / "run.json", args.overwrite,
                    "exists: the folder holds a simulation already")
    start = time.perf_counter()
    output = simulate(scenario, args.out, codec=args.codec)
    seconds = time.perf_counter() - start
    print(f"{scenario.name}: {scenario.frame_count} frames "
          f"{output.run.parent.parent.name}/ in {seconds:.1f} s")
    for key in ("video", "serial", "sd_log", "run", "spots", "frames", "line", "camera_imu",
                "surfaces", "lateral_video"):
        if getattr(output, key) is not None:
            print(f"  {key:<13} {getattr(output, key)}")
    for board in output.lateral_boards:
        print(f"  {'lateral_board':<13} {board}")
    return 0
