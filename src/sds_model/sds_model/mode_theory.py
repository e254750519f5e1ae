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


def mode_name(order: int, index: int) -> str:
    """lateral_n for order 1, axisymmetric_n for order 0, m<order>n<index> otherwise."""
    return {1: f"lateral_{index}", 0: f"axisymmetric_{index}"}.get(order, f"m{order}n{index}")


@dataclass(frozen=True)
class TheoreticalMode:
    """A container mode's name, root ξ and linear natural frequency [Hz]."""

    name: str
    order: int
    index: int
    xi: float
    frequency_hz: float


THEORY_MODES = ((1, 1), (1, 2), (1, 3), (0, 1))
"""Lateral modes 1–3 and the first axisymmetric mode, as in the method notes."""


def theoretical_modes(radius_mm: float, depth_mm: float, gravity_m_s2: float,
                      surface_tension_n_m: float, density_kg_m3: float,
                      modes: tuple[tuple[int, int], ...] = THEORY_MODES) -> list[TheoreticalMode]:
    """Linear frequencies of a flat free surface with surface tension (valid in 1 g).

    At g → 0 only the capillary term is left; it assumes a flat interface with a 90° contact
    angle, which a real microgravity meniscus (or a magnetised ferrofluid) does not have, so
    give measured or modelled frequencies for drops instead.
    """
    return [TheoreticalMode(mode_name(order, index), order, index, mode_root(order, index),
                            natural_frequency_hz(mode_root(order, index), radius_mm, depth_mm,
                                                 gravity_m_s2, surface_tension_n_m,
                                                 density_kg_m3))
            for order, index in modes]
