"""Live previews shed while the chain runs behind its frames, and said so on the console.

A live preview (spots as measured, their points) is worth making only while it is fresh: when
the chain falls behind the camera, making it costs the CPU that the recorded measurements
need, and what it shows is already old. The recorded topics are never shed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from rclpy.node import Node
from std_msgs.msg import Header

REPORT_PERIOD_S = 10.0
"""While shedding goes on, how often the console hears how much was shed [s]."""


@dataclass
class LiveShedding:
    """Whether a frame's live preview is still worth making, by how late the frame comes.

    A frame's lateness is its lag (the receiving clock minus its stamp) beyond the smallest
    lag seen so far: stamps on another clock with a constant offset (a replay's) work alike,
    and the chain's own fastest path counts as on time. A frame later than `max_lag_s` is shed.
    `keep` counts; `report` gives the console's line when shedding starts, every
    REPORT_PERIOD_S while it goes on, and when it ends.
    """

    what: str                         # the preview, as the console names it
    max_lag_s: float
    baseline_s: float = math.inf      # the smallest lag seen [s]
    shed: int = 0                     # since the last report
    made: int = 0                     # since the last report
    worst_late_s: float = 0.0         # since the last report
    shedding_since_s: float | None = None
    last_report_s: float = -math.inf
    shed_in_all: int = 0

    def keep(self, lag_s: float) -> bool:
        """True if the preview of a frame that came `lag_s` after its stamp is to be made."""
        self.baseline_s = min(self.baseline_s, lag_s)
        late_s = lag_s - self.baseline_s
        if late_s > self.max_lag_s:
            self.shed += 1
            self.shed_in_all += 1
            self.worst_late_s = max(self.worst_late_s, late_s)
            return False
        self.made += 1
        return True

    def report(self, now_s: float) -> str | None:
        """The console's line about shedding at `now_s` [s, any monotonic clock], or None."""
        if self.shed and self.shedding_since_s is None:
            self.shedding_since_s = self.last_report_s = now_s
            line = (f"{self.what}: shedding the frames more than {self.max_lag_s * 1e3:.0f} ms "
                    f"late (up to {self.worst_late_s:.2f} s): the chain is behind its camera; "
                    "the recorded measurements are complete")
        elif self.shedding_since_s is not None and not self.shed and self.made:
            line = (f"{self.what}: back in time, {self.shed_in_all} frames shed over "
                    f"{now_s - self.shedding_since_s:.1f} s")
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


def lag_s(node: Node, header: Header) -> float:
    """How long after its stamp a message is handled [s], on the node's clock."""
    return (node.get_clock().now().nanoseconds
            - (header.stamp.sec * 1_000_000_000 + header.stamp.nanosec)) * 1e-9
