"""The `sds` command: one entry point, one subcommand per job."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sds_bringup.graph import GraphFileError, apply_overrides, composed, load_graph
from sds_bringup.launcher import Launcher
from sds_bringup.ros_env import graph_environment, pick_domain_id


def _add_graph(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser(
        "graph", help="start the nodes of a graph file as processes",
        description="Start a graph (config/graphs/*.yaml); Ctrl-C or SIGTERM stops every node.",
    )
    parser.add_argument("graph_file", type=Path)
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="NODE.PARAM=VALUE", help="override a node parameter (YAML value)")
    parser.add_argument("--compose", action="store_true",
                        help="host every node in one process instead of one process each")
    parser.add_argument("--domain-id", type=int, default=None,
                        help="ROS_DOMAIN_ID for the graph (default: a random one in 1..101)")
    parser.set_defaults(run=_run_graph)


def _run_graph(args: argparse.Namespace) -> int:
    try:
        entries = apply_overrides(load_graph(args.graph_file), args.overrides)
    except GraphFileError as error:
        print(f"sds graph: {error}", file=sys.stderr)
        return 2
    if args.compose:
        entries = composed(entries)
    domain_id = pick_domain_id() if args.domain_id is None else args.domain_id
    print(f"sds graph: {args.graph_file} on ROS_DOMAIN_ID={domain_id} (localhost only)")
    return Launcher(entries, graph_environment(domain_id)).run()


def _add_demo(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser(
        "demo", help="run the graph on built-in data and print a summary",
        description="Make a short clip, stream it through the graph, and report what arrived.",
    )
    parser.add_argument("--out", type=Path, default=Path("demo_output"))
    parser.add_argument("--seconds", type=float, default=5.0, help="clip length [s]")
    parser.set_defaults(run=_run_demo)


def _run_demo(args: argparse.Namespace) -> int:
    from sds_bringup.demo import run_demo

    return run_demo(args.out, args.seconds)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of `sds` with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="sds",
        description="Sloshing Detection Subsystem: laser-based free-surface measurement.",
    )
    commands = parser.add_subparsers(title="commands", required=True, metavar="COMMAND")
    _add_graph(commands)
    _add_demo(commands)
    return parser


def main(argv: list[str] | None = None) -> None:
    """Entry point of the `sds` command."""
    args = build_parser().parse_args(argv)
    raise SystemExit(args.run(args))
