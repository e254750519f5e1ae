"""Still stretches of a tilt-table video: where nothing in the container's image moves.

A calibration video holds the table at each known angle for a while, moving (and sloshing)
in between. Frame k's change is the number of pixels whose red value differs from frame
k − 1's by more than `CHANGE_LEVEL` (below the spot threshold, above sensor and codec noise);
a stretch of frames whose every change is at most `still_px` and that lasts `min_frames` or
more is a plateau, and its middle frame stands for it.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

CHANGE_LEVEL = 25.0
"""Grey levels a pixel must change by between frames to count as motion."""


@dataclass(frozen=True)
class Plateau:
    """Frames `first`…`last` (inclusive) in which nothing moved."""

    first: int
    last: int

    @property
    def middle(self) -> int:
        """The frame that stands for the plateau."""
        return (self.first + self.last) // 2


def changed_pixels(previous: np.ndarray, current: np.ndarray,
                   level: float = CHANGE_LEVEL) -> int:
    """How many pixels differ by more than `level` between two frames of the same shape."""
    return int(np.count_nonzero(cv2.absdiff(previous, current) > level))


def find_plateaus(changes: np.ndarray, min_frames: int, still_px: int = 0) -> list[Plateau]:
    """The plateaus of a video from its per-frame changes (`changes[k]`: frame k against
    frame k − 1; `changes[0]` is ignored), each at least `min_frames` long."""
    changes = np.asarray(changes)
    plateaus, first = [], 0
    for k in range(1, len(changes) + 1):
        if k == len(changes) or changes[k] > still_px:
            if k - first >= min_frames:
                plateaus.append(Plateau(first, k - 1))
            first = k
    return plateaus
