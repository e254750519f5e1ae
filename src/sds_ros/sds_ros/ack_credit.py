"""Flow control by acknowledgement: the frame_ack protocol of flood pacing, written once.

A publisher that floods (the frame source, the player) registers each frame's stamp before it
publishes it; every consumer (tracker, recorder) publishes that frame's header on `frame_ack`
once it is done with it. A frame is settled when `consumers` acks with its stamp have come. The
publisher waits for credit (at most `limit` frames unsettled) before the next frame, so nothing
is dropped and no queue grows; an ack for a stamp it did not register is ignored.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from rclpy.time import Time
from std_msgs.msg import Header

STALL_WARNING_S = 5.0
"""How long a wait for credit lasts before each warning that names the stalled frame."""


class AckCredit:
    """The frames published and not yet acknowledged by every consumer, by stamp [ns]."""

    def __init__(self, consumers: int, topic: str, warn: Callable[[str], object]) -> None:
        self.consumers = consumers
        self._topic = topic
        self._warn = warn
        self._acked: dict[int, int] = {}   # stamp [ns] -> acks received
        self._condition = threading.Condition()
        self._released = False

    @property
    def unsettled(self) -> int:
        """How many registered frames still await an ack."""
        with self._condition:
            return len(self._acked)

    def register(self, stamp_ns: int) -> None:
        """A frame with this stamp is about to be published."""
        with self._condition:
            self._acked[stamp_ns] = 0

    def on_ack(self, msg: Header) -> None:
        """Subscription callback of `frame_ack`: count one consumer's ack."""
        stamp_ns = Time.from_msg(msg.stamp).nanoseconds
        with self._condition:
            if stamp_ns in self._acked:
                self._acked[stamp_ns] += 1
                if self._acked[stamp_ns] >= self.consumers:
                    del self._acked[stamp_ns]
                self._condition.notify_all()

    def wait(self, limit: int) -> None:
        """Block until at most `limit` frames are unsettled (or `release()`), warning every
        STALL_WARNING_S with the oldest frame's stamp and its acks."""
        with self._condition:
            while not self._condition.wait_for(
                    lambda: len(self._acked) <= limit or self._released, STALL_WARNING_S):
                oldest = min(self._acked)
                self._warn(f"{len(self._acked)} frame(s) still await "
                           f"acknowledgement on {self._topic}; the oldest (stamp {oldest} ns) "
                           f"has {self._acked[oldest]} of {self.consumers}")

    def drain(self, timeout_s: float) -> bool:
        """Wait up to `timeout_s` for every frame to settle, without warnings; True if they
        did."""
        with self._condition:
            return self._condition.wait_for(lambda: not self._acked or self._released,
                                            timeout_s) and not self._acked

    def release(self) -> None:
        """Wake every waiter for good (the node is stopping)."""
        with self._condition:
            self._released = True
            self._condition.notify_all()
