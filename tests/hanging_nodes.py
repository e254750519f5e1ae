"""Nodes that hang while their graph process stops: the graph processes' watchdogs at work."""

from __future__ import annotations

import time

from sds_ros.hosted_node import HostedNode

HANG_S = 60.0


class HangsInTeardownNode(HostedNode):
    """Done half a second after it starts; then its destruction hangs, as a middleware's
    teardown can (the node host's watchdog ends it)."""

    def __init__(self, node_name: str, **node_kwargs) -> None:
        super().__init__(node_name, **node_kwargs)
        self.create_timer(0.5, self.finished.set)

    def destroy_node(self) -> None:
        time.sleep(HANG_S)
        super().destroy_node()


class HangsInCloseNode(HostedNode):
    """Its close() never returns in time (the launcher dumps its stacks and kills it)."""

    def close(self) -> None:
        time.sleep(HANG_S)
