"""The Arduino's clock mapped to the host's: offset and drift, updated online.

A record is stamped by the device (micros(), wrapping) and received a little later by the
host: host = offset + rate · device + delay, delay ≥ 0. The line through the lowest point of
host − device in each second over a sliding window estimates offset and rate; the delays,
always positive, only lift points above it.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import minimize_scalar
from scipy.signal import savgol_filter

from sds_arduino.protocol import WRAP

WINDOW_S = 60.0
"""Pairs older than this (device time) are forgotten: the drift may change with temperature."""
BIN_S = 1.0
"""The lowest point of each second of device time enters the fit."""
DRIFT_BINS = 10
"""Bins before a drift is fitted: over fewer seconds a millisecond of delay jitter tilts the
line by 1e-3 (fitted over 3 s, stamps were 16 ms off at 4 s); a 40 ppm drift costs 0.4 ms
over the 10 s the offset alone serves."""


class DeviceClock:
    """Unwraps micros() and maps device time [s] to host time [s]."""

    _bins: deque[list[float]]    # [second of device time, device time, lowest host − device]
    _last_ticks: int | None      # the last micros() value seen
    _elapsed_us: int

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
        if len(self._bins) <= DRIFT_BINS:   # too short for a drift: offset alone
            self.rate, self.offset_s = 1.0, float(lowest.min())
            return
        # The current second is not over: its lowest point so far may be any record's delay
        # (50 ms tilted the line by 1e-3).
        slope, intercept = np.polyfit(device[:-1], lowest[:-1], 1)
        self.rate, self.offset_s = 1.0 + float(slope), float(intercept)

    def to_host(self, device_s: float) -> float:
        """Host time [s] of a device time [s] (NaN before the first observation)."""
        return self.offset_s + self.rate * device_s

    def reset(self) -> None:
        """Forget the mapping (a new device session: micros() from 0)."""
        self._bins = deque()
        self._last_ticks = None
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


@dataclass(frozen=True)
class ClockLink:
    """Camera time minus device time [s] with its one-sigma uncertainty, from the device-time
    window [s] around the excitation where the two accelerometers were compared."""

    offset_s: float
    sigma_s: float
    window_s: tuple[float, float]
    residual_m_s2: float


EXCITATION_WINDOW_S = 1.0
"""Device time compared around the excitation (its strongest change) [s]."""
REFINE_S = 0.1
"""Half width of the fine search around the coarse offset [s]."""
GRID_S = 0.0005
"""Step of the fine search before the sub-step refinement [s]."""
EDGE_SAMPLES = 4
"""Samples over which the excitation's change is measured (20 ms at 200 Hz)."""
EXCITATION_CONTRAST = 8.0
"""An excitation's change is at least this many times the stream's median change."""
SLOPE_SMOOTHING_SAMPLES = 7
"""Savitzky–Golay window (cubic) of the camera stream whose slope enters σ."""
DEVICE_RANGE_M_S2 = 16 * 9.80665
"""The Arduino's MPU6050 range (±16 g, sds_arduino.protocol)."""


def _excitation_time_s(times_s: np.ndarray, values: np.ndarray) -> float | None:
    """Where a stream changes most (a kick's edges, a release's step, a launch) [s]: the
    largest change over EDGE_SAMPLES samples; None if it does not stand out from the
    stream's ordinary changes (no excitation: noise alone)."""
    change = np.linalg.norm(values[EDGE_SAMPLES:] - values[:-EDGE_SAMPLES], axis=1)
    index = int(np.argmax(change))
    if change[index] <= EXCITATION_CONTRAST * max(float(np.median(change)), 1e-9):
        return None
    return float(0.5 * (times_s[index] + times_s[index + EDGE_SAMPLES]))


def align_by_acceleration(device_t_s: np.ndarray, device_m_s2: np.ndarray,
                          camera_t_s: np.ndarray, camera_m_s2: np.ndarray,
                          window_s: float = EXCITATION_WINDOW_S,
                          device_range_m_s2: float = DEVICE_RANGE_M_S2) -> ClockLink | None:
    """The camera's clock against the device's from the same excitation seen by both
    accelerometers (N×k each, in one frame, e.g. both turned into the rig's, or k = 1 for
    magnitudes); None when either shows no excitation or they do not overlap around it.

    Coarse: each stream's strongest change. Fine: the offset τ that minimises
    Σ |d(t) − c(t + τ)|² over the device samples within `window_s` around the excitation
    (medians removed; the camera's stream a cubic spline, so that the cost is smooth in τ;
    device samples at its range, `device_range_m_s2`, left out: the catapult's launch clips
    the MPU6050), on a 0.5 ms grid and then by Brent's method. σ is the Cramér–Rao bound
    σ_r / √Σ|ċ|² with σ_r the residual's scatter and ċ the slope of the smoothed stream.
    """
    device_t_s, camera_t_s = np.asarray(device_t_s, float), np.asarray(camera_t_s, float)
    device = np.asarray(device_m_s2, float).reshape(len(device_t_s), -1)
    camera = np.asarray(camera_m_s2, float).reshape(len(camera_t_s), -1)
    if len(device) <= 2 * EDGE_SAMPLES or len(camera) <= 2 * EDGE_SAMPLES:
        return None
    centre = _excitation_time_s(device_t_s, device)
    seen = _excitation_time_s(camera_t_s, camera)
    if centre is None or seen is None:
        return None
    coarse = seen - centre
    inside = (np.abs(device_t_s - centre) <= window_s / 2) & \
        (np.abs(device) < 0.99 * device_range_m_s2).all(axis=1)
    t, d = device_t_s[inside], device[inside] - np.median(device[inside], axis=0)
    spline = CubicSpline(camera_t_s, camera - np.median(camera, axis=0), extrapolate=False)

    def cost(offset: float) -> float:
        return float(np.nanmean(np.sum((d - spline(t + offset)) ** 2, axis=1)))

    offsets = coarse + np.arange(-REFINE_S, REFINE_S + GRID_S / 2, GRID_S)
    costs = np.array([cost(o) for o in offsets])
    if not np.isfinite(costs).any():
        return None
    best = float(offsets[int(np.nanargmin(costs))])
    offset = float(minimize_scalar(cost, bounds=(best - GRID_S, best + GRID_S),
                                   method="bounded", options={"xatol": 1e-6}).x)
    matched = spline(t + offset)
    valid = np.isfinite(matched).all(axis=1)
    residual = d[valid] - matched[valid]
    # The slope's energy from the smoothed stream: the noise's own slope would inflate it.
    smooth = CubicSpline(camera_t_s, savgol_filter(camera, SLOPE_SMOOTHING_SAMPLES, 3, axis=0),
                         extrapolate=False)
    slope = smooth(t[valid] + offset, 1)
    scatter = float(np.sqrt(np.sum(residual**2) / max(residual.size - 1, 1)))
    energy = float(np.sum(slope**2))
    sigma = scatter / np.sqrt(energy) if energy > 0 else float("inf")
    return ClockLink(offset, sigma, (float(t[0]), float(t[-1])), scatter)
