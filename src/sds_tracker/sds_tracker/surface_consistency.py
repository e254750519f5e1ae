"""The surface most of a frame's points lie on, found whatever a few far-off ones say.

A diode's spot can only be where its beam meets the liquid (`spots.beam_points_at`): a
wall's reflection, a glint or the container's rim on a diode's path stands for a point tens
of mm above or below the surface the other spots show. The surface is fitted robustly
(least median of squares over minimal sets, then least squares on its inliers) as
z = a + b·x + c·y + d·(x² + y²), which holds a still's plane exactly (`fit_robust_surface`;
the tracker judges stills' spots against it, `SpotTracker._on_the_surface`). Not the
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

SURFACE_TERMS = 4
"""Coefficients of the fitted surface (a, b, c, d); also the points of a minimal set."""
SURFACE_SAMPLES = 64
"""Minimal sets tried for the least median of squares: with 3 wrong points of 20, half of
all sets are free of them, so a clean one is missed with probability 2⁻⁶⁴ (with 5 of 20,
28 % are: 10⁻⁹)."""
SURFACE_RANDOM_SEED = 0
"""The minimal sets are drawn with this seed: one frame always gives the same answer."""
DEGENERATE = 1e-9
"""Singular values below this share of the largest are a term the points do not determine
(x and y are scaled to about 1, so the terms' columns are alike in size)."""


@dataclass(frozen=True)
class RobustSurface:
    """z = a + b·x + c·y + d·(x² + y² − `mean_square`) [mm] with x and y in units of
    `scale_mm` (the points' reach, so that the terms' columns are alike in size) and the
    bulge taken about the fitted points' mean square distance from the axis (where they are
    all at one distance, its column is zero and the fit a plane), as `fit_robust_surface`
    fits it."""

    coefficients: np.ndarray
    scale_mm: float
    mean_square: float

    def heights_above_mm(self, points_mm: np.ndarray) -> np.ndarray:
        """Each point's height above the surface [mm] (N×3 points → N)."""
        design = _design(points_mm, self.scale_mm, self.mean_square)
        return points_mm[:, 2] - design @ self.coefficients


def _design(points_mm: np.ndarray, scale_mm: float, mean_square: float) -> np.ndarray:
    """The surface's design matrix for points (…×3 mm): 1, x, y, x² + y² − `mean_square`
    (x, y in units of `scale_mm`)."""
    x, y = points_mm[..., 0] / scale_mm, points_mm[..., 1] / scale_mm
    return np.stack([np.ones_like(x), x, y, x**2 + y**2 - mean_square], axis=-1)


def fit_robust_surface(points_mm: np.ndarray, inlier_mm: float) -> RobustSurface:
    """The surface (N×3 points [mm], N > SURFACE_TERMS) that most points lie on: of
    SURFACE_SAMPLES minimal sets (SURFACE_TERMS points each), the one whose surface has the
    least median squared residual, refitted by least squares to the points within
    `inlier_mm` of it. Where the points do not determine every term (all at one distance
    from the axis: no bulge; on one line: no tilt across it), the least-norm solution,
    which leaves that term out."""
    count = len(points_mm)
    scale_mm = max(float(np.abs(points_mm[:, :2]).max()), 1e-9)
    draws = np.random.default_rng(SURFACE_RANDOM_SEED).random((SURFACE_SAMPLES, count))
    sets = np.argsort(draws, axis=1)[:, :SURFACE_TERMS]   # each row: distinct points
    mean_square = float(np.mean(np.sum((points_mm[:, :2] / scale_mm) ** 2, axis=1)))
    design, heights = _design(points_mm, scale_mm, mean_square), points_mm[:, 2]
    solvers = np.linalg.pinv(design[sets], rtol=DEGENERATE)
    coefficients = np.einsum("skn,sn->sk", solvers, heights[sets])
    residuals = heights - coefficients @ design.T
    best = int(np.argmin(np.median(residuals**2, axis=1)))
    inliers = np.abs(residuals[best]) <= inlier_mm
    if inliers.sum() <= SURFACE_TERMS:
        return RobustSurface(coefficients[best], scale_mm, mean_square)
    fitted, *_ = np.linalg.lstsq(design[inliers], heights[inliers], rcond=DEGENERATE)
    return RobustSurface(fitted, scale_mm, mean_square)
