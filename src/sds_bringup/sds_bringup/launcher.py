"""Start graph processes, prefix their logs, and shut every one down on exit or signal."""

from __future__ import annotations

import ctypes
import functools
import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import IO

from sds_bringup.graph import NodeEntry

_PR_SET_PDEATHSIG = 1
GRACE_PERIOD_S = 10.0


def _prepare_child(nice: int) -> None:
    """In the child: receive SIGTERM when the launcher dies, even by SIGKILL (Linux); lower
    the priority by `nice`."""
    ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    if nice:
        os.nice(nice)


@dataclass
class GraphProcess:
    """One OS process hosting one or more nodes."""

    name: str
    entries: list[NodeEntry]
    popen: subprocess.Popen[bytes] | None = None

    @property
    def required(self) -> bool:
        """Whether the graph ends when this process exits."""
        return any(entry.required for entry in self.entries)

    @property
    def nice(self) -> int:
        """The process's niceness: the highest its nodes ask for."""
        return max(entry.nice for entry in self.entries)

    def command(self) -> list[str]:
        """The node host command line (python -O drops the generated messages' asserts)."""
        specs = [
            {"plugin": e.plugin, "name": e.name, "ros_args": e.ros_args(), "required": e.required}
            for e in self.entries
        ]
        return [sys.executable, "-O", "-m", "sds_bringup.node_host", json.dumps(specs)]


def group_processes(entries: list[NodeEntry]) -> list[GraphProcess]:
    """Group nodes by their process name, in order of first appearance."""
    processes: dict[str, GraphProcess] = {}
    for entry in entries:
        processes.setdefault(entry.process, GraphProcess(entry.process, [])).entries.append(entry)
    return list(processes.values())


class Launcher:
    """Run a graph's processes until a required one exits, all exit, or SIGINT/SIGTERM."""

    def __init__(
        self,
        entries: list[NodeEntry],
        env: dict[str, str],
        output: IO[str] | None = None,
        grace_period_s: float = GRACE_PERIOD_S,
    ) -> None:
        self.processes = group_processes(entries)
        self.env = env
        self.output = output or sys.stdout
        self.grace_period_s = grace_period_s
        self._stop = threading.Event()
        self._print_lock = threading.Lock()
        self._log_threads: list[threading.Thread] = []

    def request_stop(self, *_: object) -> None:
        """Ask the graph to shut down (signal handler and API)."""
        self._stop.set()

    @property
    def stopping(self) -> bool:
        """Whether a shutdown was asked for."""
        return self._stop.is_set()

    def run(self, on_started: Callable[[], None] | None = None) -> int:
        """Start every process, wait, shut down; return the first non-zero exit code or 0."""
        previous = {s: signal.signal(s, self.request_stop) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            self._start()
            if on_started:
                on_started()
            self._wait()
        finally:
            self._shutdown()
            for sig, handler in previous.items():
                signal.signal(sig, handler)
        codes = [process.popen.returncode for process in self.processes if process.popen]
        return next((code for code in codes if code not in (0, None)), 0)

    def _start(self) -> None:
        for process in self.processes:
            process.popen = subprocess.Popen(
                process.command(),
                env=self.env,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                start_new_session=True,
                preexec_fn=functools.partial(_prepare_child, process.nice),
            )
            self._say(process.name, f"started (pid {process.popen.pid}): "
                      + ", ".join(entry.name for entry in process.entries))
        for process in self.processes:
            thread = threading.Thread(target=self._forward_log, args=(process,), daemon=True)
            thread.start()
            self._log_threads.append(thread)

    def _wait(self) -> None:
        while not self._stop.is_set():
            running = [p for p in self.processes if p.popen and p.popen.poll() is None]
            ended_required = [p for p in self.processes if p.required and p not in running]
            if not running or ended_required:
                return
            time.sleep(0.05)

    def _shutdown(self) -> None:
        """SIGINT to every live process, then SIGKILL after the grace period."""
        live = [p for p in self.processes if p.popen and p.popen.poll() is None]
        for process in live:
            process.popen.send_signal(signal.SIGINT)
        deadline = time.monotonic() + self.grace_period_s
        for process in live:
            try:
                process.popen.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                self._say(process.name, f"did not stop in {self.grace_period_s:.0f} s: killed")
                process.popen.kill()
                process.popen.wait()
        for thread in self._log_threads:
            thread.join(timeout=2.0)
        for process in self.processes:
            if process.popen:
                self._say(process.name, f"exited with code {process.popen.returncode}")

    def _forward_log(self, process: GraphProcess) -> None:
        assert process.popen is not None and process.popen.stdout is not None
        for raw in process.popen.stdout:
            self._say(process.name, raw.decode(errors="replace").rstrip())

    def _say(self, name: str, line: str) -> None:
        with self._print_lock:
            print(f"[{name}] {line}", file=self.output, flush=True)
