"""The simulated liquid surface h(x, y, t): modes, tilt, level offset and meniscus [mm]."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
from numpy.typing import ArrayLike
from sds_model.mode_theory import ModeShape

GRADIENT_STEP_MM = 1e-4


@dataclass(frozen=True)
class ModeMotion:
    """One mode's free decay after a kick at `start_s`: q(τ) = A e^(−ζωτ) sin(ω_d τ + φ)."""

    shape: ModeShape
    amplitude_mm: float
    frequency_hz: float
    damping_ratio: float
    phase_rad: float = 0.0
    start_s: float = 0.0

    @property
    def damped_frequency_hz(self) -> float:
        """ω_d / 2π = f √(1 − ζ²)."""
        return self.frequency_hz * np.sqrt(1.0 - self.damping_ratio**2)

    def coordinate(self, time_s: ArrayLike) -> np.ndarray:
        """Modal coordinate q(t) [mm]: wall elevation along the azimuth; 0 before the kick."""
        tau = np.asarray(time_s, dtype=float) - self.start_s
        omega = 2 * np.pi * self.frequency_hz
        value = self.amplitude_mm * np.exp(-self.damping_ratio * omega * np.maximum(tau, 0.0)) * \
            np.sin(2 * np.pi * self.damped_frequency_hz * tau + self.phase_rad)
        return np.where(tau >= 0, value, 0.0)


@dataclass(frozen=True)
class Surface:
    """h(x, y, t) = Σ q_k(t) ψ_k(x, y) − x tan γx − y tan γy + offset + meniscus(r) [mm].

    Tilts are the slopes of a tilt table: the surface falls by tan γx per mm along +X.
    The meniscus rises towards the wall: height · exp(−(R − r) / length).
    """

    radius_mm: float
    modes: tuple[ModeMotion, ...] = ()
    tilt_x_rad: float = 0.0
    tilt_y_rad: float = 0.0
    offset_mm: float = 0.0
    meniscus_height_mm: float = 0.0
    meniscus_length_mm: float = 1.0

    def height(self, x_mm: ArrayLike, y_mm: ArrayLike, time_s: ArrayLike) -> np.ndarray:
        """Surface height [mm] at world (x, y) [mm] and time [s] (one time, or one per point:
        a rolling shutter sees each row at its own); inside the container."""
        x, y = np.asarray(x_mm, dtype=float), np.asarray(y_mm, dtype=float)
        height = self.offset_mm - x * np.tan(self.tilt_x_rad) - y * np.tan(self.tilt_y_rad)
        for mode in self.modes:
            q = mode.coordinate(time_s)
            if np.any(q != 0.0):
                height = height + q * mode.shape.height(x, y, self.radius_mm)
        if self.meniscus_height_mm:
            wall = self.radius_mm - np.hypot(x, y)
            height = height + self.meniscus_height_mm * np.exp(-wall / self.meniscus_length_mm)
        return height

    def normal(self, x_mm: ArrayLike, y_mm: ArrayLike, time_s: ArrayLike) -> np.ndarray:
        """Unit upward normals (N×3) by central differences of the height."""
        x, y, step = np.asarray(x_mm, dtype=float), np.asarray(y_mm, dtype=float), GRADIENT_STEP_MM
        dx = (self.height(x + step, y, time_s) - self.height(x - step, y, time_s)) / (2 * step)
        dy = (self.height(x, y + step, time_s) - self.height(x, y - step, time_s)) / (2 * step)
        normal = np.stack([-dx, -dy, np.ones_like(dx)], axis=-1)
        return normal / np.linalg.norm(normal, axis=-1, keepdims=True)

    def bound_mm(self) -> float:
        """An upper bound of |h| [mm] over the container at any time."""
        tilt = self.radius_mm * (abs(np.tan(self.tilt_x_rad)) + abs(np.tan(self.tilt_y_rad)))
        return abs(self.offset_mm) + tilt + abs(self.meniscus_height_mm) + \
            sum(abs(m.amplitude_mm) * _shape_bound(m.shape) for m in self.modes)


@cache
def _shape_bound(shape: ModeShape) -> float:
    """max |ψ| over the disc (J_m(ξ r/R)/J_m(ξ) peaks inside for higher modes)."""
    r = np.linspace(0.0, 1.0, 2001)
    return float(np.max(np.abs(shape.height(r, np.zeros_like(r), 1.0))))
