"""Helpers for tests that talk to real node processes: a spinning probe node, a graph process."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import rclpy
from conftest import DOMAIN_ID, REPO
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


def wait_until(condition: Callable[[], object], timeout: float = 30.0) -> bool:
    """Poll `condition` every 50 ms until it holds or `timeout` [s] passes."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.05)
    return False


class Probe:
    """An rclpy node in this test process, spun in a background thread."""

    def __init__(self, name: str) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = Node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self.executor.spin, daemon=True)
        self._thread.start()
        self._subscriptions: dict[str, Subscription] = {}

    def collect(self, msg_type: type, topic: str, qos: QoSProfile = RELIABLE,
                on_message: Callable | None = None) -> list:
        """Subscribe and return the list that fills with received messages."""
        received: list = []

        def callback(msg) -> None:
            received.append(msg)
            if on_message:
                on_message(msg)

        self._subscriptions[topic] = self.node.create_subscription(msg_type, topic, callback,
                                                                   qos)
        return received

    def unsubscribe(self, topic: str) -> None:
        """Stop receiving `topic` (its list keeps what came)."""
        self.node.destroy_subscription(self._subscriptions.pop(topic))

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=2.0)
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)
        self._thread.join(timeout=2.0)


class SdsGraphRun:
    """`sds graph ...` as a child process, its output collected line by line."""

    def __init__(self, graph: str | tuple[str, ...], *args: str) -> None:
        """`graph`: a file of config/graphs, or several run as one graph."""
        graph_files = [str(REPO / "config" / "graphs" / name)
                       for name in ((graph,) if isinstance(graph, str) else graph)]
        command = [str(Path(sys.executable).parent / "sds"), "graph", *graph_files,
                   "--domain-id", str(DOMAIN_ID), *args]
        self.popen = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                      env=dict(os.environ), text=True)
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.popen.stdout is not None
        for line in self.popen.stdout:
            self.lines.append(line.rstrip())

    def wait(self, timeout: float) -> int:
        """The graph's exit code; a graph still running after `timeout` [s] fails the test
        with its output."""
        try:
            code = self.popen.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"graph still running after {timeout} s:\n"
                                 + self.output()) from None
        self._reader.join(timeout=2.0)
        return code

    def wait_for_line(self, text: str, timeout: float) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for line in list(self.lines):
                if text in line:
                    return line
            time.sleep(0.05)
        raise TimeoutError(f"no line with {text!r} in:\n" + "\n".join(self.lines))

    def child_pids(self) -> list[int]:
        return [int(line.split("(pid ")[1].split(")")[0]) for line in self.lines if "(pid " in line]

    def output(self) -> str:
        return "\n".join(self.lines)

    def stop(self) -> None:
        if self.popen.poll() is None:
            self.popen.send_signal(signal.SIGTERM)
            try:
                self.wait(timeout=30)
            except AssertionError:
                self.popen.kill()
                raise


def pid_alive(pid: int) -> bool:
    """Whether a process exists and is not a zombie."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split(") ")[1].split()[0]
    except (FileNotFoundError, IndexError):
        return False
    return state != "Z"
