"""The base class of every SDS node: what the node host expects of the nodes it runs."""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from typing import Any

from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.subscription import Subscription

from sds_ros.executor import taking_either


class HostedNode(Node):
    """An rclpy node with the node host's protocol: `finished` is set when the node is done
    (a required node then ends its process; a failed one, any process), `exit_code` is the
    process's exit status it asks for (0: fine), `close()` runs before the node is destroyed
    (stop threads, finish files)."""

    def __init__(self, node_name: str, **node_kwargs) -> None:
        super().__init__(node_name, **node_kwargs)
        self.finished = threading.Event()
        self.exit_code = 0

    def declare_parameter_table(self, table: Mapping[str, Any]) -> dict[str, Any]:
        """Declare every parameter of `table` (name → default: the one place where a node's
        parameters and defaults are written) and return their values."""
        return {name: self.declare_parameter(name, default).value
                for name, default in table.items()}

    def create_subscription(self, msg_type: Any, topic: str, callback: Callable[..., None],
                            qos_profile: QoSProfile | int, **kwargs: Any) -> Subscription:
        """rclpy's `Node.create_subscription`, with a callback that takes its message's info
        given it by every executor, the graph's EventsExecutor included (`taking_either`)."""
        return super().create_subscription(msg_type, topic, taking_either(callback),
                                           qos_profile, **kwargs)

    def messages_taken(self) -> int | None:
        """How many messages the node has taken so far, for a node whose last messages must
        not be lost at a stop (a recorder, a reconstruction): once asked to stop, the node
        host takes what was delivered until this count stays put (`node_host.drain`). None
        (the default): the node is not drained."""
        return None

    def close(self) -> None:
        """Stop what the node runs beside its callbacks; nothing by default."""
