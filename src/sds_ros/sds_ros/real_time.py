"""Recorded time played in real time: a camera's file, a recording's messages. A player that
cannot keep the pace plays late and says so; it never skips to catch up."""

from __future__ import annotations

import time
from collections.abc import Callable

BEHIND_REPORT_S = 0.5
"""A moment played this far behind its due time is said on the console [s]."""
REPORT_PERIOD_S = 10.0
"""While a player stays behind, how often the console hears it [s]."""


class RealTimePace:
    """Media time played at `rate` times real time from the monotonic time `start_s` (of media
    time 0). `wait_until` sleeps until a moment is due; a moment more than BEHIND_REPORT_S past
    due is played at once, the furthest such lateness is kept (`behind_s`), and `warn` hears
    it at most every REPORT_PERIOD_S, with `cause` (what is too slow, what comes late)."""

    def __init__(self, rate: float, warn: Callable[[str], object], cause: str,
                 clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        self.rate = rate
        self.start_s = 0.0
        self.behind_s = 0.0
        self._warn = warn
        self._cause = cause
        self._clock = clock
        self._sleep = sleep
        self._last_report_s = -float("inf")

    def start(self, start_s: float) -> None:
        """Play media time 0 at the monotonic time `start_s` [s]."""
        self.start_s = start_s

    def wait_until(self, media_s: float) -> None:
        """Sleep until media time `media_s` [s] is due; keep and say how late it is if it is
        long past."""
        now_s = self._clock()
        delay_s = self.start_s + media_s / self.rate - now_s
        if delay_s > 0:
            self._sleep(delay_s)
        elif -delay_s > BEHIND_REPORT_S:
            self.behind_s = max(self.behind_s, -delay_s)
            if now_s - self._last_report_s >= REPORT_PERIOD_S:
                self._last_report_s = now_s
                self._warn(f"playing {-delay_s:.1f} s behind real time ({self._cause})")

    def behind_clause(self) -> str:
        """', up to N s behind real time' for a player's last line, or '' if it kept up."""
        return f", up to {self.behind_s:.1f} s behind real time" if self.behind_s else ""
