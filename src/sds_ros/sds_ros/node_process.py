"""The program of a graph process: `python -m sds_ros.node_process SPEC_JSON`.

A SIGINT or SIGTERM that arrives while the nodes' modules load (rclpy, OpenCV, SciPy take a
second or two) ends the process at once with code 0: nothing runs yet, and an exception raised
inside a C extension's import would turn into an ImportError with a traceback. Once the nodes
run, the node host's own handlers stop them cleanly (sds_ros.node_host).
"""

from __future__ import annotations

import os
import signal
import sys


def _stop_while_loading(*_: object) -> None:
    sys.stdout.flush()
    os._exit(0)


def main() -> None:
    """Load the node host and run the nodes of the spec given on the command line."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _stop_while_loading)
    from sds_ros.node_host import main as host_nodes

    host_nodes()


if __name__ == "__main__":
    main()
