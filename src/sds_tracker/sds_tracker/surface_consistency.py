"""The plane most of a still's points lie on, found whatever a few far-off ones say.

A diode's spot can only be where its beam meets the liquid (`spots.beam_points_at`): a
wall's reflection, a glint or the container's rim on a diode's path stands for a point tens
of mm above or below the surface the other spots show. A still's surface (a tilt, a fill
level) is a plane, fitted robustly (least median of squares over minimal sets, then least
squares on its inliers) as z = a + b·x + c·y (`fit_robust_surface`; the tracker judges
stills' spots against it, `SpotTracker._on_the_surface`, and predicts their wall reflections
from its normal, `SpotTracker._apart_from_reflections`). No bulge term d·(x² + y²): on
level and tilted development stills (rigs 7112, 7114) it took in the spots' own errors and
bent the normal at the wall by 1-2°. Not the
reconstruction's outlier rule (`sds_recon.surface_fit.surface_outliers`, leave-one-out
against the plane and three modes, one point at a time): that rule judges points already
told apart, and several ghosts at once mask each other in it (four of 20 points moved 14-40
mm, two draws: with a 5 mm limit it rejected 2 and 0 of them, and in the first two right
points as well); the least median of squares finds all four
(tests/test_surface_consistency.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SURFACE_TERMS = 3
"""Coefficients of the fitted plane (a, b, c); also the points of a minimal set."""
SURFACE_SAMPLES = 64
"""Minimal sets tried for the least median of squares: with 3 wrong points of 20, 60 % of
all sets are free of them, so a clean one is missed with probability 10⁻²⁵ (with 5 of 20,
40 % are: 10⁻¹⁴)."""
SURFACE_RANDOM_SEED = 0
"""The minimal sets are drawn with this seed: one frame always gives the same answer."""
DEGENERATE = 1e-9
"""Singular values below this share of the largest are a term the points do not determine
(x and y are scaled to about 1, so the terms' columns are alike in size)."""


@dataclass(frozen=True)
class RobustSurface:
    """z = a + b·x + c·y [mm] with x and y in units of `scale_mm` (the points' reach, so
    that the terms' columns are alike in size), as `fit_robust_surface` fits it."""

    coefficients: np.ndarray
    scale_mm: float

    def heights_above_mm(self, points_mm: np.ndarray) -> np.ndarray:
        """Each point's height above the surface [mm] (N×3 points → N)."""
        return points_mm[:, 2] - _design(points_mm, self.scale_mm) @ self.coefficients

    def beam_crossing_mm(self, beam_mm: np.ndarray) -> np.ndarray:
        """Where a beam (M×3 points along it, a polyline) first meets the surface (3 mm),
        linear between its points; NaN where it does not within them."""
        above = self.heights_above_mm(beam_mm)
        crossings = np.flatnonzero(np.sign(above[:-1]) != np.sign(above[1:]))
        if not len(crossings):
            return np.full(3, np.nan)
        k = int(crossings[0])
        share = above[k] / (above[k] - above[k + 1])
        return beam_mm[k] + share * (beam_mm[k + 1] - beam_mm[k])

    def normal(self) -> np.ndarray:
        """The plane's unit normal, up (3)."""
        _, b, c = self.coefficients
        normal = np.array([-b / self.scale_mm, -c / self.scale_mm, 1.0])
        return normal / np.linalg.norm(normal)


def _design(points_mm: np.ndarray, scale_mm: float) -> np.ndarray:
    """The plane's design matrix for points (…×3 mm): 1, x, y (x, y in units of
    `scale_mm`)."""
    x, y = points_mm[..., 0] / scale_mm, points_mm[..., 1] / scale_mm
    return np.stack([np.ones_like(x), x, y], axis=-1)


def fit_robust_surface(points_mm: np.ndarray, inlier_mm: float) -> RobustSurface:
    """The plane (N×3 points [mm], N > SURFACE_TERMS) that most points lie on: of
    SURFACE_SAMPLES minimal sets (SURFACE_TERMS points each), the one whose plane has the
    least median squared residual, refitted by least squares to the points within
    `inlier_mm` of it. Where the points do not determine every term (on one line: no tilt
    across it), the least-norm solution, which leaves that term out."""
    count = len(points_mm)
    scale_mm = max(float(np.abs(points_mm[:, :2]).max()), 1e-9)
    draws = np.random.default_rng(SURFACE_RANDOM_SEED).random((SURFACE_SAMPLES, count))
    sets = np.argsort(draws, axis=1)[:, :SURFACE_TERMS]   # each row: distinct points
    design, heights = _design(points_mm, scale_mm), points_mm[:, 2]
    solvers = np.linalg.pinv(design[sets], rtol=DEGENERATE)
    coefficients = np.einsum("skn,sn->sk", solvers, heights[sets])
    residuals = heights - coefficients @ design.T
    best = int(np.argmin(np.median(residuals**2, axis=1)))
    inliers = np.abs(residuals[best]) <= inlier_mm
    if inliers.sum() <= SURFACE_TERMS:
        return RobustSurface(coefficients[best], scale_mm)
    fitted, *_ = np.linalg.lstsq(design[inliers], heights[inliers], rcond=DEGENERATE)
    return RobustSurface(fitted, scale_mm)
