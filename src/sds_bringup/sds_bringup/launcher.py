"""Start graph processes, prefix their logs, and shut every one down on exit or signal.

The graph runs until Ctrl-C/SIGTERM, until a `required` node's process ends, until every
process has ended, or until a `needed` node's process fails (non-zero exit or killed): then the
launcher names it, its exit status and its last log lines, and stops the rest cleanly (SIGTERM),
so that the recorder closes its file. A node that is not needed (the viewer) may fail alone.
"""

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
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import IO

from sds_ros.graph_file import NodeEntry, check_plugins
from sds_ros.node_process import STACK_DUMP_SIGNAL, TEARDOWN_HUNG, TEARDOWN_LIMIT_S

_PR_SET_PDEATHSIG = 1
GRACE_PERIOD_S = 10.0
STACK_DUMP_WAIT_S = 1.0
"""How long a process that did not stop gets to write its threads' stacks before SIGKILL."""
CLEAN_STOPS = (0, -signal.SIGTERM, TEARDOWN_HUNG)
"""Exit statuses of a clean stop: done, stopped while still starting Python (SIGTERM), or
ended by its teardown watchdog after its nodes had closed."""
LAST_LINES = 6
"""Log lines of a failed process repeated in its failure report."""
RECORDER_PLUGINS = frozenset({"sds_nodes.recorder:RecorderNode"})
"""Nodes that keep what the others publish: their processes are stopped once every other
process has ended, so that they record the others' last messages (`Launcher._shutdown`)."""


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
    last_lines: deque[str] = field(default_factory=lambda: deque(maxlen=LAST_LINES))

    @property
    def required(self) -> bool:
        """Whether the graph ends when this process exits."""
        return any(entry.required for entry in self.entries)

    @property
    def needed(self) -> bool:
        """Whether the graph stops when this process fails."""
        return any(entry.needed for entry in self.entries)

    def cause(self) -> str:
        """The failure's cause: the last error line's message, else the last line."""
        errors = [line for line in self.last_lines if "[ERROR]" in line or "[FATAL]" in line
                  or line.startswith(("node host:", "Traceback"))]
        line = (errors or list(self.last_lines) or ["no output"])[-1]
        return line.split("]: ", 1)[-1]

    @property
    def records(self) -> bool:
        """Whether this process hosts a recorder (RECORDER_PLUGINS): it is stopped last."""
        return any(entry.plugin in RECORDER_PLUGINS for entry in self.entries)

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
        return [sys.executable, "-O", "-m", "sds_ros.node_process", json.dumps(specs)]


def _stop_status(code: int) -> str:
    """How a process ended, in words, once the graph has stopped."""
    if code == -signal.SIGTERM:
        return "stopped while starting"
    if code == TEARDOWN_HUNG:
        return (f"its nodes closed, but the middleware's teardown hung: ended after "
                f"{TEARDOWN_LIMIT_S:.0f} s by the node host's watchdog")
    return f"exited with code {code}"


def group_processes(entries: list[NodeEntry]) -> list[GraphProcess]:
    """Group nodes by their process name, in order of first appearance."""
    processes: dict[str, GraphProcess] = {}
    for entry in entries:
        processes.setdefault(entry.process, GraphProcess(entry.process, [])).entries.append(entry)
    return list(processes.values())


class Launcher:
    """Run a graph's processes until a required one exits, a needed one fails, all exit, or
    SIGINT/SIGTERM. Logs go to `output`; failure reports also to `console` if given."""

    def __init__(
        self,
        entries: list[NodeEntry],
        env: dict[str, str],
        output: IO[str] | None = None,
        grace_period_s: float = GRACE_PERIOD_S,
        console: IO[str] | None = None,
    ) -> None:
        check_plugins(entries)   # a wrong plugin is named before any process starts
        self.processes = group_processes(entries)
        self.env = env
        self.output = output or sys.stdout
        self.console = console
        self.grace_period_s = grace_period_s
        self.failure: str | None = None
        """One line on the first needed process that failed (None while none has)."""
        self.signal_received: int | None = None
        """The SIGINT or SIGTERM that stopped the graph (None: it ended otherwise)."""
        self._stop = threading.Event()
        self._print_lock = threading.Lock()
        self._log_threads: list[threading.Thread] = []
        self.log_error: OSError | None = None
        """Why `output` could not be written (a full disk); its lines are dropped from then
        on, so that the processes' pipes are still drained and the graph stops as it would."""

    def request_stop(self, *_: object) -> None:
        """Ask the graph to shut down (signal handler and API)."""
        self._stop.set()

    def _on_signal(self, signum: int, _frame: object) -> None:
        """Ctrl-C or a termination: remember which, then stop."""
        if self.signal_received is None:
            self.signal_received = signum
        self.request_stop()

    @property
    def stopping(self) -> bool:
        """Whether a shutdown was asked for."""
        return self._stop.is_set()

    def run(self, on_started: Callable[[], None] | None = None) -> int:
        """Start every process, wait, shut down; return the first non-zero exit code or 0."""
        previous = {s: signal.signal(s, self._on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            self._start()
            if on_started:
                on_started()
            self._wait()
            self._stop.set()
        finally:
            self._shutdown()
            for sig, handler in previous.items():
                signal.signal(sig, handler)
        codes = [process.popen.returncode for process in self.processes if process.popen]
        code = next((code for code in codes if code not in (*CLEAN_STOPS, None)), 0)
        return 128 - code if code < 0 else code   # killed by a signal: the shell's 128 + N

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
        reported: set[str] = set()
        while not self._stop.is_set():
            running = [p for p in self.processes if p.popen and p.popen.poll() is None]
            for process in self.processes:
                code = process.popen.returncode if process.popen else None
                if code not in (*CLEAN_STOPS, None) and process.name not in reported:
                    reported.add(process.name)
                    self._report_failure(process, code)
                    if process.needed:
                        return
            ended_required = [p for p in self.processes if p.required and p not in running]
            if not running or ended_required:
                return
            time.sleep(0.05)

    def _report_failure(self, process: GraphProcess, code: int) -> None:
        """Name a failed process, its exit status and its last log lines."""
        thread = self._log_threads[self.processes.index(process)]
        thread.join(timeout=1.0)   # its last lines are still on their way through the pipe
        status = f"was killed by {signal.Signals(-code).name}" if code < 0 else \
            f"exited with code {code}"
        nodes = ", ".join(entry.name for entry in process.entries)
        consequence = "stopping the graph" if process.needed else "the graph goes on without it"
        headline = f"{process.name} ({nodes}) {status}: {process.cause()}"
        if process.needed and self.failure is None:
            self.failure = headline
        report = [f"sds graph: {headline}; {consequence}. Its last lines:",
                  *(f"  [{process.name}] {line}" for line in process.last_lines)]
        with self._print_lock:
            self._write_log("\n".join(report))
            if self.console is not None and self.console is not self.output:
                print("\n".join(report), file=self.console, flush=True)

    def _shutdown(self) -> None:
        """SIGTERM to every live process but the recorders' (`GraphProcess.records`), then,
        once those have ended, to the recorders': what the others published up to their end
        is recorded. In each wave, after the grace period, a process still alive writes its
        threads' stacks to the log (STACK_DUMP_SIGNAL), then gets SIGKILL. (SIGTERM, not
        SIGINT: a process still starting Python dies of it quietly, where SIGINT would raise
        KeyboardInterrupt with a traceback; the node host handles both alike.)"""
        live = [p for p in self.processes if p.popen and p.popen.poll() is None]
        self._terminate([p for p in live if not p.records])
        self._terminate([p for p in live if p.records])
        for thread in self._log_threads:
            thread.join(timeout=2.0)
        for process in self.processes:
            if process.popen:
                self._say(process.name, _stop_status(process.popen.returncode))

    def _terminate(self, processes: list[GraphProcess]) -> None:
        """SIGTERM to each of `processes`; wait for them for the grace period, then dump the
        stacks of and kill each one still alive."""
        live = [(p.name, p.popen) for p in processes if p.popen]
        for _, popen in live:
            popen.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + self.grace_period_s
        for name, popen in live:
            try:
                popen.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                self._say(name, f"did not stop in {self.grace_period_s:.0f} s: its threads' "
                          "stacks follow; killed")
                popen.send_signal(STACK_DUMP_SIGNAL)
                try:
                    popen.wait(timeout=STACK_DUMP_WAIT_S)
                except subprocess.TimeoutExpired:
                    popen.kill()
                    popen.wait()

    def _forward_log(self, process: GraphProcess) -> None:
        assert process.popen is not None and process.popen.stdout is not None
        for raw in process.popen.stdout:
            line = raw.decode(errors="replace").rstrip()
            process.last_lines.append(line)
            self._say(process.name, line)

    def _say(self, name: str, line: str) -> None:
        with self._print_lock:
            self._write_log(f"[{name}] {line}")

    def _write_log(self, text: str) -> None:
        """Append to `output` (under the print lock) until it fails; then say once on the
        console why the log stops there (`log_error`)."""
        if self.log_error is not None:
            return
        try:
            print(text, file=self.output, flush=True)
        except OSError as error:
            self.log_error = error
            if self.console is not None:
                print(f"sds graph: the graph's log cannot be written ({error.strerror}): "
                      "its lines from here on are lost", file=self.console, flush=True)
