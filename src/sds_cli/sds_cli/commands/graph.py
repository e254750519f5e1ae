"""`sds graph`: start the nodes of a graph file as processes."""

from __future__ import annotations

import argparse
import signal
import sys

from sds_cli.commands import CommandError, existing_file


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds graph`."""
    parser = commands.add_parser(
        "graph", help="start the nodes of a graph file as processes",
        description="Start a graph (config/graphs/*.yaml; several files make one graph, e.g. "
                    "drop.yaml lateral.yaml); Ctrl-C or SIGTERM stops every node.",
    )
    parser.add_argument("graph_files", type=existing_file, nargs="+", metavar="graph_file",
                        help="graph files, e.g. config/graphs/drop.yaml (and "
                             "config/graphs/lateral.yaml for the side camera)")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="NODE.PARAM=VALUE", help="override a node parameter (YAML value)")
    parser.add_argument("--compose", action="store_true",
                        help="host every node in one process instead of one process each")
    parser.add_argument("--domain-id", type=int, default=None,
                        help="ROS_DOMAIN_ID for the graph (default: the environment's, else a "
                             "random one in 1..101)")
    parser.add_argument("--network", action="store_true",
                        help="part of a graph across machines: discover this machine and the "
                             "peers in ROS_STATIC_PEERS, one domain (--domain-id) on all")
    parser.set_defaults(run=run, command="graph")


def run(args: argparse.Namespace) -> int:
    """Run the graph until it ends; its exit code (128 + the signal when Ctrl-C or SIGTERM
    stopped it, as a shell reports a process a signal ended)."""
    from sds_bringup.launcher import Launcher
    from sds_bringup.ros_env import graph_domain_id, graph_environment
    from sds_ros.graph_file import apply_overrides, check_plugins, composed, load_graph
    entries = [entry for path in args.graph_files for entry in load_graph(path)]
    names = [entry.name for entry in entries]
    twice = sorted({name for name in names if names.count(name) > 1})
    if twice:
        raise CommandError(f"the graph files name the node(s) {', '.join(twice)} more than "
                           "once")
    entries = apply_overrides(entries, args.overrides)
    if args.compose:
        entries = composed(entries)
    check_plugins(entries)   # before the banner: a refused graph says one line
    domain_id = graph_domain_id(args.domain_id, args.network)
    environment = graph_environment(domain_id, network=args.network)
    peers = environment.get("ROS_STATIC_PEERS", "")
    print(f"sds graph: {' + '.join(str(p) for p in args.graph_files)} on "
          f"ROS_DOMAIN_ID={domain_id}, discovery "
          f"{environment['ROS_AUTOMATIC_DISCOVERY_RANGE']}" + (f" + peers {peers}" if peers
                                                              else ""))
    launcher = Launcher(entries, environment)
    code = launcher.run()
    if launcher.signal_received is not None:   # stopped by Ctrl-C or SIGTERM: the shell's code
        print(f"sds graph: stopped by {signal.Signals(launcher.signal_received).name}",
              file=sys.stderr)
        return 128 + launcher.signal_received
    return code
