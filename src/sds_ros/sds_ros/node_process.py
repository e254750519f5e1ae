"""The program of a graph process: `python -m sds_ros.node_process SPEC_JSON`.

A SIGINT or SIGTERM that arrives while the nodes' modules load (rclpy, OpenCV, SciPy take a
second or two) ends the process at once with code 0: nothing runs yet, and an exception raised
inside a C extension's import would turn into an ImportError with a traceback. Once the nodes
run, the node host's own handlers stop them cleanly (sds_ros.node_host).

Two watchdogs act outside Python, so that they work even where a C extension holds the GIL:
STACK_DUMP_SIGNAL writes every thread's stack to stderr (the launcher sends it to a process
that does not stop in time, before it kills it), and `arm_teardown_watchdog` ends a process
whose middleware teardown hangs after its nodes have closed.
"""

from __future__ import annotations

import faulthandler
import os
import signal
import sys

STACK_DUMP_SIGNAL = signal.SIGUSR1
"""On this signal a graph process writes every thread's Python stack to stderr."""
TEARDOWN_LIMIT_S = 5.0
"""How long the middleware may take to tear down once every node has closed."""
TEARDOWN_HUNG = -signal.SIGALRM
"""The exit status (as subprocess reports it) of a process ended by the teardown watchdog: its
nodes had closed, their files and last words were out, so it stopped cleanly."""


def arm_teardown_watchdog() -> None:
    """After TEARDOWN_LIMIT_S, print every thread's stack and end the process by SIGALRM.

    Called once the nodes have closed, in a process that is about to exit. A graph process has
    been seen not to stop (once, in CI; where it hung is not known). Destroying a node deletes
    its DDS participant inside rcl_node_fini, which holds the GIL: a hang there would block any
    Python timer, so both the dump and the alarm are the C library's. The process normally
    exits long before either fires."""
    faulthandler.dump_traceback_later(TEARDOWN_LIMIT_S - 0.5)
    signal.signal(signal.SIGALRM, signal.SIG_DFL)
    signal.setitimer(signal.ITIMER_REAL, TEARDOWN_LIMIT_S)


def _stop_while_loading(*_: object) -> None:
    sys.stdout.flush()
    os._exit(0)


def main() -> None:
    """Load the node host and run the nodes of the spec given on the command line."""
    faulthandler.register(STACK_DUMP_SIGNAL, all_threads=True)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _stop_while_loading)
    from sds_ros.node_host import main as host_nodes

    host_nodes()


if __name__ == "__main__":
    main()
