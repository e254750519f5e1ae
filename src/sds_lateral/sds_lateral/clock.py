"""The side camera's clock against the top camera's, by the sync LED (seed Sec. 3).

A switch of the LED shows in the first frame after it, so a camera with frame period T sees
it late by U(0, T): T/2 is taken off, σ = T/√12. Two paths link the side camera to the top
camera, and each gives top time minus side time:
- direct: both cameras see the same switch-on (σ² = (T_top² + T_side²)/12; 9.9 ms for 30 and
  125 fps, since the top camera's 33 ms frames dominate);
- through the Arduino: the side camera's switch-on against the Arduino's own LED record, and
  the top camera against the Arduino by acceleration (`sds_arduino.clock`, 0.01–0.7 ms), which
  shares no measurement with the direct path.
Where both exist they are combined by their inverse variances and their difference is given
in its σ: a wrong LED region, a dropped frame or a camera IMU offset from its frames shows
there. The side clock's drift over a drop (a crystal's 20 ppm: 0.2 ms in 10 s) is left out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from sds_arduino.clock import camera_offset_s
from sds_camera.led import switch_sigma_s, switch_times_s
from sds_model.errors import InputError


@dataclass(frozen=True)
class ClockPath:
    """Top camera time minus side camera time [s] by one path, with its σ [s]."""

    name: str
    offset_s: float
    sigma_s: float


@dataclass(frozen=True)
class LateralClock:
    """The paths found, their inverse-variance combination [s] and σ [s], and (two paths) the
    first minus the second in their combined σ."""

    paths: tuple[ClockPath, ...]
    offset_s: float
    sigma_s: float
    disagreement_sigmas: float | None

    def top_time_s(self, lateral_time_s: ArrayLike) -> np.ndarray:
        """Side frame times [s, its own clock] on the top camera's clock."""
        return np.asarray(lateral_time_s, dtype=float) + self.offset_s

    def summary(self) -> str:
        """One line: the combined offset and each path."""
        parts = ", ".join(f"{p.name} {p.offset_s * 1e3:+.1f} ± {p.sigma_s * 1e3:.1f} ms"
                          for p in self.paths)
        text = (f"side clock: top − side = {self.offset_s * 1e3:+.1f} ± "
                f"{self.sigma_s * 1e3:.1f} ms ({parts})")
        if self.disagreement_sigmas is not None:
            text += f"; the paths differ by {self.disagreement_sigmas:+.1f} σ"
        return text


class ClockError(InputError):
    """No path links the side camera's clock to the top camera's."""


def link_lateral_clock(lateral_on_s: list[float], lateral_period_s: float,
                       top_on_s: list[float] | None = None, top_period_s: float | None = None,
                       device_on_s: list[float] | None = None,
                       top_minus_device: tuple[float, float] | None = None) -> LateralClock:
    """Top time minus side time from the first frames showing the LED on, on each camera's
    clock (`top_on_s` already carried to the LED's rows under a rolling shutter), and from
    the Arduino's LED switch-ons [s, device clock] with the top camera's offset to the device
    (offset, σ [s]) where given; ClockError when no path exists."""
    side = switch_times_s(lateral_on_s, lateral_period_s)
    side_sigma = switch_sigma_s(lateral_period_s)
    paths = []
    if top_on_s and top_period_s and side:
        top = switch_times_s(top_on_s, top_period_s)
        offset = camera_offset_s(side, top)
        paths.append(ClockPath("LED, direct", offset,
                               float(np.hypot(switch_sigma_s(top_period_s), side_sigma))))
    if device_on_s and top_minus_device is not None and side:
        side_minus_device = camera_offset_s(device_on_s, side)
        paths.append(ClockPath("LED to the Arduino, its acceleration to the top camera",
                               top_minus_device[0] - side_minus_device,
                               float(np.hypot(top_minus_device[1], side_sigma))))
    paths = [p for p in paths if np.isfinite(p.offset_s)]
    if not paths:
        raise ClockError("no LED switch-on seen by the side camera and by the top camera or "
                         "the Arduino: check the side view's led_roi_px and the --led-roi")
    weights = np.array([1 / p.sigma_s**2 for p in paths])
    offsets = np.array([p.offset_s for p in paths])
    disagreement = None
    if len(paths) == 2:
        disagreement = float((offsets[0] - offsets[1])
                             / np.hypot(paths[0].sigma_s, paths[1].sigma_s))
    return LateralClock(tuple(paths), float(weights @ offsets / weights.sum()),
                        float(1 / np.sqrt(weights.sum())), disagreement)
