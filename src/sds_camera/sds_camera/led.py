"""The sync LED in the video: its on/off switches, from the brightness of a small region."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MIN_CONTRAST = 40.0
"""Brightness levels between off and on before any switch is believed (8-bit frames)."""


@dataclass(frozen=True)
class LedSwitch:
    """The LED went on (True) or off at this frame."""

    frame: int
    on: bool


class LedDetector:
    """Hysteresis on the mean brightness of the LED's region; levels learned as frames pass.

    The LED is on in a frame when its brightness is above the middle of the darkest and
    brightest seen so far, once they differ by MIN_CONTRAST; a switch is the first frame of a
    new state.
    """

    def __init__(self, region: tuple[int, int, int, int]) -> None:
        x, y, width, height = region
        self.window = (slice(y, y + height), slice(x, x + width))
        self.low, self.high = np.inf, -np.inf
        self.on: bool | None = None

    def brightness(self, frame: np.ndarray) -> float:
        """Mean of the brightest quarter of the region's pixels (brightest channel), so that
        a generous region around a small LED still sees it switch."""
        patch = frame[self.window]
        values = (patch.max(axis=2) if patch.ndim == 3 else patch).ravel()
        count = max(1, values.size // 4)
        return float(np.partition(values, values.size - count)[-count:].mean())

    def update(self, index: int, frame: np.ndarray) -> LedSwitch | None:
        """The switch this frame shows, if any."""
        level = self.brightness(frame)
        self.low, self.high = min(self.low, level), max(self.high, level)
        if self.high - self.low < MIN_CONTRAST:
            return None
        on = level > (self.low + self.high) / 2
        switched = self.on is not None and on != self.on
        if self.on is None and on:
            switched = True   # on from the first contrasting frame: the off frames came before
        self.on = on
        return LedSwitch(index, on) if switched else None


def switch_times_s(first_frame_s: list[float], period_s: float) -> list[float]:
    """The LED's switch times [s] from the times of the first frames showing its new state:
    a switch shows in the first frame after it, late by U(0, T) for a frame period T, so T/2
    is taken off (σ: `switch_sigma_s`)."""
    return [t - period_s / 2 for t in first_frame_s]


def switch_sigma_s(period_s: float) -> float:
    """The σ of a switch time from `switch_times_s` [s]: T/√12."""
    return period_s / math.sqrt(12)
