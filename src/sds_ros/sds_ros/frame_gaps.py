"""Messages that never reached a subscriber: frames from the gaps in their stamps, any
message from the gaps in its publisher's sequence numbers.

A reliable keep-last writer drops a message its slow reader has not taken once newer ones
fill its history: the reader then never sees it, and nothing in the stream says so. The
frames of a camera or a video come at a steady period, so a gap of several periods between
two stamps is the frames that went missing in between, wherever they were lost (the camera's
driver, or the way to this reader); the middleware numbers every message a publisher writes,
so a gap in those numbers is exactly what was lost on the way to this reader.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np
from rclpy.subscription import MessageInfo

PERIOD_FRAMES = 15
"""Stamp differences the frame period is the median of."""
GAP_PERIODS = 1.5
"""A difference longer than this many periods holds missing frames."""


@dataclass
class FrameGaps:
    """How many frames are missing before each new stamp, and in all."""

    missed_in_all: int = 0
    _last_s: float | None = None
    _periods_s: deque[float] = field(default_factory=lambda: deque(maxlen=PERIOD_FRAMES))

    def missed(self, stamp_s: float) -> int:
        """The frames missing between the previous stamp and `stamp_s` [s] (0 until the
        period is known from PERIOD_FRAMES differences; a stamp going back resets it)."""
        last, self._last_s = self._last_s, stamp_s
        if last is None or stamp_s <= last:
            self._periods_s.clear()
            return 0
        step_s = stamp_s - last
        if len(self._periods_s) < PERIOD_FRAMES:
            self._periods_s.append(step_s)
            return 0
        period_s = float(np.median(self._periods_s))
        if step_s <= GAP_PERIODS * period_s:
            self._periods_s.append(step_s)
            return 0
        missing = round(step_s / period_s) - 1
        self.missed_in_all += missing
        return missing


class PublisherGaps:
    """Messages a subscriber never got, from the gaps in each publisher's sequence numbers:
    between two it got (`missed_in_all`), and before the first it got from each publisher
    (`before_first`: a publisher numbers its messages from 1, so a subscriber that matched
    late, or a latched topic whose history was shorter than what it had published, starts
    past 1)."""

    def __init__(self) -> None:
        self.missed_in_all = 0
        self.before_first = 0
        self._last: dict[bytes, int] = {}

    def missed(self, info: MessageInfo) -> int:
        """Messages of this one's publisher missing since its previous one (0 at the first
        from a publisher, whose number adds to `before_first` instead)."""
        sequence = info.get("publication_sequence_number")
        gid = info.get("publisher_gid")
        if sequence is None or gid is None:
            return 0
        key = bytes(gid["data"])
        last, self._last[key] = self._last.get(key), sequence
        if last is None:
            self.before_first += max(sequence - 1, 0)
            return 0
        if sequence <= last:
            return 0
        missing = sequence - last - 1
        self.missed_in_all += missing
        return missing
