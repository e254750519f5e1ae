"""Linear sloshing modes of an upright cylinder (method notes, "Lateral sloshing in 1 g")."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import j0, j1, jnp_zeros, jv


@cache
def mode_root(order: int, index: int) -> float:
    """ξ: the `index`-th zero of J'_order (order 1: lateral 1.8412, 5.3314, 8.5363; 0: 3.8317)."""
    return float(jnp_zeros(order, index)[index - 1])


@dataclass(frozen=True)
class ModeShape:
    """Free-surface shape J_m(ξ r / R) / J_m(ξ) · cos(m (θ − azimuth)), 1 at the wall."""

    order: int
    index: int
    azimuth_rad: float = 0.0

    @property
    def xi(self) -> float:
        """The mode's root ξ."""
        return mode_root(self.order, self.index)

    def height(self, x_mm: ArrayLike, y_mm: ArrayLike, radius_mm: float) -> np.ndarray:
        """Shape value at world (x, y) [mm] for a container of `radius_mm`."""
        x, y = np.asarray(x_mm, dtype=float), np.asarray(y_mm, dtype=float)
        r, theta = np.hypot(x, y), np.arctan2(y, x)
        radial = _bessel(self.order, self.xi * r / radius_mm) / _bessel(self.order, self.xi)
        return radial * np.cos(self.order * (theta - self.azimuth_rad))


def _bessel(order: int, x: np.ndarray | float) -> np.ndarray:
    """J_order(x); the dedicated J0 and J1 are ten times faster than the general jv."""
    return j0(x) if order == 0 else j1(x) if order == 1 else jv(order, x)


def natural_frequency_hz(xi: float, radius_mm: float, depth_mm: float, gravity_m_s2: float,
                         surface_tension_n_m: float = 0.0, density_kg_m3: float = 1000.0) -> float:
    """ω² = (g ξ / R + σ ξ³ / (ρ R³)) tanh(ξ h / R), returned as ω / 2π [Hz]."""
    radius, depth = radius_mm * 1e-3, depth_mm * 1e-3
    capillary = surface_tension_n_m * xi**3 / (density_kg_m3 * radius**3)
    stiffness = gravity_m_s2 * xi / radius + capillary
    return float(np.sqrt(stiffness * np.tanh(xi * depth / radius)) / (2 * np.pi))
