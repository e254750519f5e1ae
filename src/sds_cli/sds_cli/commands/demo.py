"""`sds demo`: simulate a drop, measure it with the whole graph, compare with the truth."""

from __future__ import annotations

import argparse
from pathlib import Path

from sds_cli.commands import output_folder, positive_float


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds demo`."""
    parser = commands.add_parser(
        "demo", help="calibrate a simulated rig as built, measure a drop with it through the "
                     "whole graph, compare with the truth",
        description="Draw a rig as built from the StELIUM rig file (leaning beams, camera pose, "
                    "emitters, the camera file's intrinsics and readout within their σ, a real "
                    "camera's imaging), calibrate it as a user does (sds calibrate plan, the "
                    "tilt table's images, sds calibrate rig), simulate the drop of "
                    "config/scenarios/drop_4p7s.yaml with that rig, run the whole chain on it "
                    "as node processes (camera, tracker, reconstruction, Arduino bridge on a "
                    "pseudo-terminal, recorder, Rerun) with the calibrated rig file, analyse "
                    "the recording and print the results next to the simulator's truth.",
    )
    parser.add_argument("--out", type=output_folder, default=Path("demo_output"),
                        help="the demo's own folder (rewritten on each run)")
    parser.add_argument("--seconds", type=positive_float,
                        help="simulated duration [s] (default: the scenario's)")
    parser.add_argument("--exact-rig", action="store_true",
                        help="render and measure the drop with the scenario's own rig file (no "
                             "rig as built, no calibration, clean imaging)")
    parser.set_defaults(run=run, command="demo")


def run(args: argparse.Namespace) -> int:
    """The demo; 0 when every frame was measured."""
    from sds_bringup.chain import run_chain
    from sds_workflows.demo import run_demo

    return run_demo(args.out, args.seconds, run_chain, args.exact_rig)
