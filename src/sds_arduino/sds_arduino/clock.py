"""The Arduino's clock mapped to the host's: offset and drift, updated online.

A record is stamped by the device (micros(), wrapping) and received a little later by the
host: host = offset + rate · device + delay, delay ≥ 0. The line through the lowest point of
host − device in each second over a sliding window estimates offset and rate; the delays,
always positive, only lift points above it.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from sds_arduino.protocol import WRAP

WINDOW_S = 60.0
"""Pairs older than this (device time) are forgotten: the drift may change with temperature."""
BIN_S = 1.0
"""The lowest point of each second of device time enters the fit."""


class DeviceClock:
    """Unwraps micros() and maps device time [s] to host time [s]."""

    def __init__(self, window_s: float = WINDOW_S) -> None:
        self.window_s = window_s
        self.reset()

    def device_seconds(self, t_us: int) -> float:
        """Device time [s] since the first record, across micros() wraps."""
        if self._last_ticks is not None:
            self._elapsed_us += (t_us - self._last_ticks) % WRAP
        self._last_ticks = t_us
        return self._elapsed_us * 1e-6

    def observe(self, device_s: float, host_s: float) -> None:
        """A record's device time and the host time it arrived at; refits the mapping."""
        difference = host_s - device_s
        index = int(device_s // BIN_S)
        if not self._bins or self._bins[-1][0] != index:
            self._bins.append([index, device_s, difference])
        elif difference < self._bins[-1][2]:
            self._bins[-1][1:] = [device_s, difference]
        while self._bins[0][0] < index - self.window_s / BIN_S:
            self._bins.popleft()
        _, device, lowest = np.array(self._bins).T
        if len(self._bins) < 3:   # too short for a drift: offset alone
            self.rate, self.offset_s = 1.0, float(lowest.min())
            return
        slope, intercept = np.polyfit(device, lowest, 1)
        self.rate, self.offset_s = 1.0 + float(slope), float(intercept)

    def to_host(self, device_s: float) -> float:
        """Host time [s] of a device time [s] (NaN before the first observation)."""
        return self.offset_s + self.rate * device_s

    def reset(self) -> None:
        """Forget the mapping (a new device session: micros() from 0)."""
        self._bins: deque[list[float]] = deque()
        self._last_ticks: int | None = None
        self._elapsed_us = 0
        self.offset_s = float("nan")
        self.rate = 1.0


def camera_offset_s(device_on_s: list[float], camera_on_s: list[float]) -> float:
    """Camera time minus device time [s] of the same sync-LED switch-ons (median over the
    pairs, matched in order); NaN without a pair."""
    pairs = min(len(device_on_s), len(camera_on_s))
    if pairs == 0:
        return float("nan")
    return float(np.median(np.subtract(camera_on_s[:pairs], device_on_s[:pairs])))
