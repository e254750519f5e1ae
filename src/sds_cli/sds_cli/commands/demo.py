"""`sds demo`: simulate a drop, measure it with the whole graph, compare with the truth."""

from __future__ import annotations

import argparse
from pathlib import Path

from sds_cli.commands import output_folder, positive_float


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds demo`."""
    parser = commands.add_parser(
        "demo", help="simulate a drop, measure it with the whole graph, compare with the truth",
        description="Simulate a 4.7 s drop (config/scenarios/drop_4p7s.yaml), run the whole "
                    "chain on it as node processes (camera, tracker, reconstruction, Arduino "
                    "bridge on a pseudo-terminal, recorder, Rerun), analyse the recording and "
                    "print the results next to the simulator's truth.",
    )
    parser.add_argument("--out", type=output_folder, default=Path("demo_output"),
                        help="the demo's own folder (rewritten on each run)")
    parser.add_argument("--seconds", type=positive_float,
                        help="simulated duration [s] (default: the scenario's)")
    parser.set_defaults(run=run, command="demo")


def run(args: argparse.Namespace) -> int:
    """The demo; 0 when every frame was measured."""
    from sds_bringup.chain import run_chain
    from sds_workflows.demo import run_demo

    return run_demo(args.out, args.seconds, run_chain)
