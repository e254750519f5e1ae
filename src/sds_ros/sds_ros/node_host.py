"""Host one or more nodes in one process until a required node finishes or a signal arrives.

A hosted node class takes (node_name, cli_args=...) like rclpy's Node; a `HostedNode`
(sds_ros.hosted_node) also tells the host when it is done (`finished`), the exit status it asks
for (`exit_code`), and is closed (`close()`) before it is destroyed.
The launcher runs it as `python -m sds_ros.node_process SPEC_JSON`, where SPEC_JSON is
a list of {"plugin": "module:Class", "name": ..., "ros_args": [...], "required": bool}.
"""

from __future__ import annotations

import importlib
import json
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence

import rclpy
from rclpy.executors import Executor, ExternalShutdownException
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from sds_model.errors import InputError

from sds_ros.executor import graph_executor
from sds_ros.hosted_node import HostedNode
from sds_ros.node_process import arm_teardown_watchdog
from sds_ros.qos import unacknowledged

NodeFactory = Callable[..., Node]
EXIT_STARTUP_ERROR = 3
DRAIN_QUIET_S = 0.5
"""At a stop, how long a drained node's count of messages taken must stay put before what
was delivered to it counts as taken [s]. Its publishers have ended by then (the launcher
stops the recorders last): what they sent is in its readers, taken back to back."""
DRAIN_LIMIT_S = 5.0
"""At a stop, the longest the node host drains [s] (within the launcher's grace period)."""
STOP_ACK_S = 2.0
"""As its nodes end (at a stop and at the graph's end), the longest the node host waits for
their readers to acknowledge what they published last [s], the nodes drained and the
others each (within the launcher's grace period)."""


def load_plugin(plugin: str) -> NodeFactory:
    """The node class named by 'package.module:Class'."""
    module_name, _, class_name = plugin.partition(":")
    if not class_name:
        raise InputError(f"node plugin {plugin!r} must look like 'package.module:Class'")
    return getattr(importlib.import_module(module_name), class_name)


def run_nodes(
    entries: Sequence[tuple[NodeFactory, str, bool]]
    | Sequence[tuple[NodeFactory, str, bool, list[str]]],
    args: list[str] | None = None,
) -> int:
    """Spin (factory, name, required[, ros_args]) nodes; return the worst node exit code.

    A process's main: once the nodes have closed, the teardown watchdog is armed
    (sds_ros.node_process.arm_teardown_watchdog)."""
    # SIGINT/SIGTERM end the loop below, not the context: the nodes' last words in close()
    # (files written, final counts) still reach /rosout.
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    executor = graph_executor()
    nodes: list[Node] = []
    required: list[Node] = []
    exit_code = 0
    try:
        for factory, name, is_required, *ros_args in entries:
            node = factory(name, cli_args=ros_args[0] if ros_args else None)
            nodes.append(node)
            executor.add_node(node)
            if is_required:
                required.append(node)
            if _failed(node):   # it cannot work (a missing source): start no more of them
                break
        # Until a required node is done, or any node has failed (a node that cannot work,
        # e.g. a recorder refusing to replace a file, ends its process with its code).
        while rclpy.ok() and not stop.is_set() and \
                not any(_finished(node) for node in required) and \
                not any(_failed(node) for node in nodes):
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception as error:
        print(f"node host: {type(error).__name__}: {error}", file=sys.stderr, flush=True)
        exit_code = EXIT_STARTUP_ERROR
    finally:
        # The nodes that are drained (a recorder, a reconstruction) close last: stopped, the
        # others (a camera, a tracker in the same process) stop publishing first, their last
        # messages reach every reader (a drained node in this process too), then what was
        # delivered is taken.
        hosted = [node for node in nodes if isinstance(node, HostedNode)]
        drained = [node for node in hosted if node.messages_taken() is not None]
        for node in [node for node in hosted if node not in drained]:
            node.close()
            executor.remove_node(node)   # no callback of a closed node while draining
        if rclpy.ok():
            wait_for_readers([node for node in nodes if node not in drained], STOP_ACK_S)
        if stop.is_set() and drained and rclpy.ok():
            drain(executor, drained)
        for node in drained:
            node.close()
        if rclpy.ok():
            wait_for_readers(drained, STOP_ACK_S)
        exit_code = max([exit_code, *(node.exit_code for node in hosted)])
        arm_teardown_watchdog()
        executor.shutdown(timeout_sec=1.0)
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown()
    return exit_code


def drain(executor: Executor, nodes: list[HostedNode]) -> None:
    """Spin until the count of messages taken (`HostedNode.messages_taken`) of each of
    `nodes` stays put for DRAIN_QUIET_S: the messages already delivered to them are taken.
    Each node says so when DRAIN_LIMIT_S runs out first."""
    deadline = time.monotonic() + DRAIN_LIMIT_S
    counts, quiet_since = [node.messages_taken() for node in nodes], time.monotonic()
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
        now = [node.messages_taken() for node in nodes]
        if now != counts:
            counts, quiet_since = now, time.monotonic()
        elif time.monotonic() - quiet_since >= DRAIN_QUIET_S:
            return
    for node in nodes:
        node.get_logger().warning(
            f"stopped while messages were still coming {DRAIN_LIMIT_S:g} s after the stop: "
            "the last ones may be missing")


def wait_for_readers(nodes: Sequence[Node], timeout_s: float) -> None:
    """Wait until the readers of every publisher of `nodes` have acknowledged what it sent,
    for at most `timeout_s` [s] in all: what a node published as it closed (a camera's last
    packets, a tracker's last spots, a reconstruction's last fit) reaches the recorder
    before this process ends. Each publisher still waiting then says so."""
    owners = {publisher: node for node in nodes for publisher in node.publishers}
    for publisher in unacknowledged(list(owners), timeout_s, threading.Event()):
        owners[publisher].get_logger().warning(
            f"stopped before every reader of {publisher.topic_name} acknowledged its "
            "last messages: they may be missing there")


def _failed(node: Node) -> bool:
    return isinstance(node, HostedNode) and node.finished.is_set() and node.exit_code != 0


def _finished(node: Node) -> bool:
    return isinstance(node, HostedNode) and node.finished.is_set()


def main() -> None:
    """Entry point of the graph processes started by the launcher."""
    specs = json.loads(sys.argv[1])
    entries = [
        (load_plugin(spec["plugin"]), spec["name"], spec["required"], spec["ros_args"])
        for spec in specs
    ]
    raise SystemExit(run_nodes(entries, args=[sys.argv[0]]))
