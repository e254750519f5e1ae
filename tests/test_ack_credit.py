"""The frame_ack flow control shared by the frame source and the player (no graph needed)."""

from __future__ import annotations

import threading
import time

import pytest
from builtin_interfaces.msg import Time
from sds_ros.ack_credit import AckCredit
from std_msgs.msg import Header

from sds_ros import ack_credit


def ack(stamp_ns: int) -> Header:
    return Header(stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9))


def test_a_frame_settles_once_every_consumer_acked_it() -> None:
    credit = AckCredit(2, "/camera/frame_ack", print)
    credit.register(1_500_000_000)
    credit.register(2_000_000_000)
    credit.on_ack(ack(1_500_000_000))
    credit.on_ack(ack(7))                  # a stamp never registered: ignored
    assert credit.unsettled == 2
    credit.on_ack(ack(1_500_000_000))
    assert credit.unsettled == 1
    assert not credit.drain(timeout_s=0.05)
    credit.on_ack(ack(2_000_000_000))
    credit.on_ack(ack(2_000_000_000))
    assert credit.drain(timeout_s=0.05)


def test_wait_blocks_until_acks_give_credit_and_warns_while_stalled(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(ack_credit, "STALL_WARNING_S", 0.05)
    warnings: list[str] = []
    credit = AckCredit(1, "/camera/frame_ack", warnings.append)
    for stamp in (10, 20):
        credit.register(stamp)
    acker = threading.Timer(0.3, credit.on_ack, [ack(10)])
    acker.start()
    start = time.monotonic()
    credit.wait(1)
    assert time.monotonic() - start >= 0.25 and credit.unsettled == 1
    assert warnings and "the oldest (stamp 10 ns) has 0 of 1" in warnings[0]
    assert "/camera/frame_ack" in warnings[0]


def test_release_wakes_a_waiter_that_no_ack_would() -> None:
    credit = AckCredit(1, "frame_ack", print)
    credit.register(1)
    threading.Timer(0.1, credit.release).start()
    credit.wait(0)                          # returns: the node is stopping
    assert credit.unsettled == 1
