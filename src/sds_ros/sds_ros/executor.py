"""The executor every graph process spins, and what its callbacks that take their message's
info need.

rclpy's EventsExecutor dispatches callbacks from C++: taking what a recorder records per 4K
frame (a 260 kB packet, 20 IMU samples, three clouds) costs 1.5 ms of CPU with it and 7.7-8.3
ms with the SingleThreadedExecutor (`bench/executor.py`; bench/README, "the graph on rclpy's
EventsExecutor"), on a machine where the live chain needs every core it has. In rclpy 9.1.2
(Kilted) it calls a callback that takes the message's info (`rclpy.subscription.MessageInfo`:
its publisher's sequence number and source time) with one argument, the pair (message, info)
(`HandleSubscriptionReady` in rclpy's `events_executor.cpp`), where rclpy's own executors pass
the two; such a callback is wrapped in `WithMessageInfo`, which takes either. Every SDS node
subscribes through `HostedNode.create_subscription`, which wraps it (`taking_either`), so a
node's callback is written as for rclpy's own executors.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

from rclpy.executors import Executor
from rclpy.experimental import EventsExecutor
from rclpy.subscription import MessageInfo

_MESSAGE_AND_INFO = inspect.Signature([
    inspect.Parameter("message", inspect.Parameter.POSITIONAL_ONLY),
    inspect.Parameter("info", inspect.Parameter.POSITIONAL_ONLY)])


class WithMessageInfo:
    """A subscription callback `callback(message, info)` that any of rclpy's executors calls
    with the message's info: its signature has the two parameters (so rclpy passes the info),
    and it takes them as two arguments or as the one pair that the EventsExecutor passes."""

    __signature__ = _MESSAGE_AND_INFO

    def __init__(self, callback: Callable[[Any, MessageInfo], None]) -> None:
        self.callback = callback

    def __call__(self, *arguments: Any) -> None:
        message, info = arguments[0] if len(arguments) == 1 else arguments
        self.callback(message, info)


def _callable_with(callback: Callable[..., None], arguments: int) -> bool:
    """Whether `callback` can be called with `arguments` positional arguments."""
    try:
        inspect.signature(callback).bind(*[object()] * arguments)
    except TypeError:
        return False
    return True


def taking_either(callback: Callable[..., None]) -> Callable[..., None]:
    """`callback` as every executor calls it: wrapped in `WithMessageInfo` where rclpy would
    give it the message's info (it cannot be called with the message alone but can with the
    message and its info, as rclpy's `Subscription.callback` decides), else itself (a callback
    that takes neither is left for rclpy to refuse)."""
    if (isinstance(callback, WithMessageInfo) or _callable_with(callback, 1)
            or not _callable_with(callback, 2)):
        return callback
    return WithMessageInfo(callback)


def graph_executor() -> Executor:
    """A new EventsExecutor on the default context: what a graph process spins."""
    return EventsExecutor()
