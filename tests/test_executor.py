"""The graph's executor: an SDS node's callbacks that take their message's info get it from
either of rclpy's executors, written as for rclpy's own (`HostedNode.create_subscription`,
`sds_ros.executor.taking_either`)."""

from __future__ import annotations

import time

import pytest
import rclpy
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from ros_helpers import RELIABLE
from sds_ros.executor import WithMessageInfo, taking_either
from sds_ros.hosted_node import HostedNode
from std_msgs.msg import String

pytestmark = pytest.mark.ros

MESSAGES = 5


@pytest.mark.parametrize("make_executor", [SingleThreadedExecutor, EventsExecutor],
                         ids=["single-threaded", "events"])
@pytest.mark.parametrize("raw", [False, True], ids=["message", "serialized"])
def test_a_callback_that_takes_the_info_gets_each_message_with_its_own(make_executor,
                                                                        raw: bool) -> None:
    """Published 5 times to an SDS node whose callback takes (message, info), not wrapped by
    the node: each message once, in order, with its publisher's sequence number (one more each
    time) and a source time no later than its reception."""
    context = rclpy.Context()
    rclpy.init(context=context)
    executor: Executor = make_executor(context=context)
    publisher_node = Node("executor_test_publisher", context=context)
    subscriber_node = HostedNode("executor_test_subscriber", context=context)
    received: list[tuple[object, dict, int]] = []

    def take(message: object, info: dict) -> None:
        received.append((message, info, time.time_ns()))

    try:
        for node in (publisher_node, subscriber_node):
            executor.add_node(node)
        publisher = publisher_node.create_publisher(String, "executor_test", RELIABLE)
        subscriber_node.create_subscription(String, "executor_test", take, RELIABLE, raw=raw)
        deadline = time.monotonic() + 10.0
        while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        for index in range(MESSAGES):
            publisher.publish(String(data=f"message {index}"))
        while len(received) < MESSAGES and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
    finally:
        executor.shutdown(timeout_sec=1.0)
        for node in (publisher_node, subscriber_node):
            node.destroy_node()
        rclpy.shutdown(context=context)
    assert len(received) == MESSAGES
    for index, (message, _, _) in enumerate(received):
        if raw:
            assert isinstance(message, bytes) and f"message {index}".encode() in message
        else:
            assert message == String(data=f"message {index}")
    sequence = [info["publication_sequence_number"] for _, info, _ in received]
    assert sequence == list(range(sequence[0], sequence[0] + MESSAGES))
    assert all(0 < info["source_timestamp"] <= taken_ns for _, info, taken_ns in received)


def test_only_a_callback_that_needs_the_info_is_wrapped() -> None:
    """rclpy's rule (`Subscription.callback`): a callback callable with the message alone gets
    the message alone, one that needs (message, info) is wrapped, and one that takes neither is
    left for rclpy to refuse."""
    def message_only(message: object) -> None: ...
    def message_and_info(message: object, info: dict) -> None: ...
    def message_and_optional_info(message: object, info: dict | None = None) -> None: ...
    def three(a: object, b: object, c: object) -> None: ...
    wrapped = WithMessageInfo(message_and_info)
    assert taking_either(message_only) is message_only
    assert taking_either(message_and_optional_info) is message_and_optional_info
    assert isinstance(taking_either(message_and_info), WithMessageInfo)
    assert taking_either(message_and_info).callback is message_and_info
    assert taking_either(wrapped) is wrapped
    assert taking_either(three) is three
