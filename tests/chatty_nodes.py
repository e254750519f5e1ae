"""A node that writes much to its log and is then done: the launcher must keep reading it."""

from __future__ import annotations

from sds_ros.hosted_node import HostedNode

LINES = 3000
"""Log lines it writes: about 300 kB, several times a pipe's 64 kB."""


class ChattyNode(HostedNode):
    """Writes LINES log lines at start, then is done."""

    def __init__(self, node_name: str, **node_kwargs) -> None:
        super().__init__(node_name, **node_kwargs)
        for index in range(LINES):
            self.get_logger().info(f"line {index} of {LINES}: " + "x" * 60)
        self.finished.set()
