"""When each image row is exposed: a CMOS camera's rolling shutter, from its camera file.

A rolling shutter reads the rows one after the other over `readout_s` [s] (in the camera
file: `readout_s`, and `readout_direction`, top_to_bottom by default). The one definition of
time used everywhere: a frame's stamp is the exposure middle of the row read first; row y (full
frame, fractional rows allowed) is exposed `readout_s · y / height_px` later (top to bottom;
bottom to top: counted from the last row). `readout_s: 0` (or absent) is a global shutter.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from sds_model.camera.model import CameraModelError

DIRECTIONS = ("top_to_bottom", "bottom_to_top")


@dataclass(frozen=True)
class RollingShutter:
    """The rows' readout: its duration [s] and direction (0 s: a global shutter)."""

    readout_s: float = 0.0
    direction: str = DIRECTIONS[0]

    def row_time_s(self, y_px: ArrayLike, height_px: int) -> np.ndarray:
        """How long after the frame's stamp row `y_px` is exposed [s] (see the module)."""
        rows = np.asarray(y_px, dtype=float)
        if self.direction == "bottom_to_top":
            rows = (height_px - 1) - rows
        return self.readout_s * rows / height_px


def rolling_shutter(content: dict[str, Any]) -> RollingShutter:
    """A camera file's `readout_s` and `readout_direction` (absent: a global shutter)."""
    try:
        readout_s = float(content.get("readout_s") or 0.0)
    except (TypeError, ValueError) as error:
        raise CameraModelError(f"readout_s must be a duration in seconds: {error}") from error
    direction = content.get("readout_direction", DIRECTIONS[0])
    if not 0.0 <= readout_s < 1.0:
        raise CameraModelError(f"readout_s must be from 0 (global shutter) to under 1 s, got "
                               f"{readout_s:g}")
    if direction not in DIRECTIONS:
        raise CameraModelError(f"readout_direction must be one of {list(DIRECTIONS)}, got "
                               f"{direction!r}")
    return RollingShutter(readout_s, str(direction))
