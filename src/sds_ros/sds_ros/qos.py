"""QoS of the measuring chain's data topics, the start-up wait for their consumers and the
end-of-stream wait for their acknowledgements."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence

from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

STREAM_DEPTH = 300
"""Messages a stream's writer keeps, for readers that lag and late ones: 10 s at 30 fps (a
niced process on a busy machine matched 2.4 s late; a line profile is 45 kB, 13 MB kept)."""


def stream_qos(depth: int = STREAM_DEPTH) -> QoSProfile:
    """Reliable, keep-last `depth`, transient-local: spots, line, points, fits and estimates
    (not frames: docs/graph.md), for writers and readers alike.

    A writer counts a new reader a moment before that reader has matched the writer, and a
    volatile Fast DDS reader never gets what was written in between (eProsima/Fast-DDS#2641):
    the first results of a drop slipped past the recorder. A transient-local reader asks for
    the writer's kept messages when it matches, so none of the first `depth` is lost. A
    volatile writer cannot feed these readers (incompatible durability, logged by rclpy).
    """
    return QoSProfile(depth=depth, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def start_when_consumed(node: Node, outputs: Sequence[tuple[Publisher, int]],
                        start: Callable[[], None], period_s: float = 0.05) -> None:
    """Call `start` (e.g. subscribe to the node's inputs) once every output publisher has at
    least its count of subscriptions (e.g. the recorder): at once if no count is positive."""
    wanted = [(publisher, count) for publisher, count in outputs if count > 0]
    if not wanted:
        start()
        return
    node.get_logger().info("waiting for " + ", ".join(
        f"{count} subscriber(s) on {publisher.topic_name}" for publisher, count in wanted))

    def check() -> None:
        if all(publisher.get_subscription_count() >= count for publisher, count in wanted):
            timer.cancel()
            start()

    timer = node.create_timer(period_s, check)


ACK_POLL_S = 0.02
"""How often `unacknowledged` asks whether everything is acknowledged [s]."""

ASK_SHARE = 0.1
"""The largest share of a wait for acknowledgements spent asking when asking itself blocks."""


def wait_for_acks(publisher: Publisher, timeout_s: float, stop: threading.Event) -> bool:
    """Wait until every reader has acknowledged what `publisher` sent, for at most `timeout_s`
    [s] or until `stop` is set; True once everything is acknowledged."""
    return not unacknowledged([publisher], timeout_s, stop)


def unacknowledged(publishers: Sequence[Publisher], timeout_s: float,
                   stop: threading.Event) -> list[Publisher]:
    """Wait until the readers of every one of `publishers` have acknowledged what it sent, for
    at most `timeout_s` [s] in all or until `stop` is set; the publishers still waiting then,
    and those not asked before the time ran out ([] once everything is acknowledged).

    rclpy's own `wait_for_all_acked(timeout)` holds the GIL for the whole wait: with a stopped
    reader, a 10 s wait in one thread froze every other thread of the process (executor and
    signal handlers included) for 10 s (Kilted wheels). So this asks without waiting, every
    ACK_POLL_S, and sleeps in between with the GIL free. Even the question can block with
    the GIL held: Fast DDS's shared-memory transport checks a stopped reader's port before it
    sends again, for its 1 s health-check timeout (one question took 1.0 to 2.0 s in
    `tests/test_qos.py` beside a running graph). After such a question this sleeps long enough
    that asking takes at most ASK_SHARE of the time, and once the time is out it asks no more.
    """
    deadline = time.monotonic() + timeout_s
    waiting = list(publishers)
    while True:
        round_start = time.monotonic()
        still_waiting = []
        for index, publisher in enumerate(waiting):
            if index > 0 and time.monotonic() >= deadline:   # out of time: the rest not asked
                still_waiting.extend(waiting[index:])
                break
            if not publisher.wait_for_all_acked(Duration(seconds=0)):
                still_waiting.append(publisher)
        waiting = still_waiting
        if not waiting:
            return []
        asking_s = time.monotonic() - round_start
        pause_s = max(ACK_POLL_S, asking_s * (1.0 - ASK_SHARE) / ASK_SHARE)
        if stop.wait(min(pause_s, max(deadline - time.monotonic(), 0.0))) \
                or time.monotonic() >= deadline:
            return waiting


LIVE_DEPTH = 5
"""Messages a live preview's writer and reader keep (the newest matters)."""


def live_qos() -> QoSProfile:
    """Best-effort, keep-last LIVE_DEPTH, volatile: the live previews (spots as measured,
    their points), REP-2003's sensor-data profile. Nobody waits for them and nothing is
    resent: a preview that misses a frame shows the next, and the recorded streams keep the
    filtered values."""
    return QoSProfile(depth=LIVE_DEPTH, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.VOLATILE)
