"""Live previews shed while the chain runs behind its frames, and said so on the console.

A live preview (spots as measured, their points) is worth making only while it is fresh: when
the chain falls behind the camera, making it costs the CPU that the recorded measurements
need, and what it shows is already old. The recorded topics are never shed.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import partial

from rclpy.node import Node
from rclpy.subscription import MessageInfo

REPORT_PERIOD_S = 10.0
"""While shedding goes on, how often the console hears how much was shed [s]."""
REPORT_CHECK_S = 1.0
"""How often a node asks its LiveShedding for a console line [s]."""
CLOCK_STEP_S = 1.0
"""A wait this much shorter than the shortest before is taken for a step of the system clock
while the message was on its way (`LiveShedding.keep`) [s]."""
NEW_OFFSET_MESSAGES = 30
"""Messages in a row that waited CLOCK_STEP_S less than the shortest wait before: the
publisher's clock now runs that much behind (it stepped for good), the new shortest wait."""


@dataclass
class LiveShedding:
    """Whether a frame's live preview is still worth making, by how late the frame comes.

    A message's lateness is how long it waited since it was published (`waited_s`) beyond the
    shortest wait seen so far (another machine's clock, a constant offset, counts as on time).
    Not its stamp: a flooding source's frames carry the video's times, hours before or after
    the clock, and a slow source lags its stamps whatever the chain does. A message later than
    `max_lag_s` is shed. A wait CLOCK_STEP_S shorter than the shortest before is a step of the
    system clock while that message was on its way: it is kept and does not become the
    shortest (it would make every later message late by the step, and the preview was shed
    for the rest of the run), unless NEW_OFFSET_MESSAGES in a row are that short.
    `keep` counts; `report` gives the console's line when shedding starts, every
    REPORT_PERIOD_S while it goes on, and when it ends.
    """

    what: str                         # the preview, as the console names it
    max_lag_s: float
    baseline_s: float = math.inf      # the shortest wait seen [s]
    shed: int = 0                     # since the last report
    made: int = 0                     # since the last report
    worst_late_s: float = 0.0         # since the last report
    shedding_since_s: float | None = None
    last_report_s: float = -math.inf
    last_shed_s: float = -math.inf    # the last report call that found something shed
    episode_shed: int = 0             # since shedding started
    stepped: int = 0                  # messages in a row CLOCK_STEP_S below the baseline

    def keep(self, waited_s: float) -> bool:
        """True if the preview of a message handled `waited_s` after it was published is to
        be made."""
        if math.isfinite(self.baseline_s) and waited_s < self.baseline_s - CLOCK_STEP_S:
            self.stepped += 1
            if self.stepped < NEW_OFFSET_MESSAGES:
                self.made += 1
                return True
        self.stepped = 0
        self.baseline_s = min(self.baseline_s, waited_s)
        late_s = waited_s - self.baseline_s
        if late_s > self.max_lag_s:
            self.shed += 1
            self.episode_shed += 1
            self.worst_late_s = max(self.worst_late_s, late_s)
            return False
        self.made += 1
        return True

    def report(self, now_s: float) -> str | None:
        """The console's line about shedding at `now_s` [s, any monotonic clock], or None:
        when shedding starts, every REPORT_PERIOD_S while it goes on, and once nothing was
        shed for REPORT_PERIOD_S."""
        if self.shed:
            self.last_shed_s = now_s
        if self.shed and self.shedding_since_s is None:
            self.shedding_since_s = self.last_report_s = now_s
            self.episode_shed = self.shed
            line = (f"{self.what}: shedding the frames more than {self.max_lag_s * 1e3:.0f} ms "
                    f"late (up to {self.worst_late_s:.2f} s): the chain is behind its camera; "
                    "the recorded measurements are complete")
        elif (self.shedding_since_s is not None and not self.shed
              and now_s - self.last_shed_s >= REPORT_PERIOD_S):
            line = (f"{self.what}: back in time, {self.episode_shed} frames shed over "
                    f"{self.last_shed_s - self.shedding_since_s:.1f} s")
            self.shedding_since_s = None
        elif self.shed and now_s - self.last_report_s >= REPORT_PERIOD_S:
            self.last_report_s = now_s
            line = (f"{self.what}: shed {self.shed} of {self.shed + self.made} frames in the "
                    f"last {REPORT_PERIOD_S:.0f} s (up to {self.worst_late_s:.2f} s late)")
        else:
            return None
        self.shed = self.made = 0
        self.worst_late_s = 0.0
        return line


def waited_s(info: MessageInfo) -> float:
    """How long ago a received message was published [s] (the middleware's source timestamp,
    on the system clock)."""
    return (time.time_ns() - info["source_timestamp"]) * 1e-9


def report_on_console(node: Node, shedding: LiveShedding) -> None:
    """Log `shedding`'s lines as `node`'s warnings (asked every REPORT_CHECK_S)."""
    node.create_timer(REPORT_CHECK_S, partial(_log_report, node, shedding))


def _log_report(node: Node, shedding: LiveShedding) -> None:
    line = shedding.report(time.monotonic())
    if line:
        node.get_logger().warning(line)
