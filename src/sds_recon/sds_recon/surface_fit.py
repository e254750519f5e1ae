"""Fits to measured surface points: the plane of seed Eq. 12, the modes, the meniscus."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from sds_model.mode_theory import ModeShape, mode_name

DEFAULT_MODES = ((1, 1), (1, 2), (0, 1))
"""Lateral modes ξ = 1.8412, 5.3314 and the first axisymmetric mode ξ = 3.8317."""
OUTLIER_LIMIT_SIGMA = 4.0
"""A point this many of its own σ off the frame's surface (or its beam) is rejected."""
HEIGHT_SIGMA_FLOOR_MM = 0.05
"""Floor under a point's height σ in that test: what the models leave (meniscus, modes)."""
MODEL_ERROR_MM = 0.3
"""What the plane and three modes leave of a strongly sloshing surface: leave-one-out residuals
of correct points reach 0.9 mm (RMS 0.4 mm) in the simulated drop right after the kick."""
LEVERAGE_FLOOR = 0.05
"""Least 1 − leverage for which a point's leave-one-out residual is judged."""
MODAL_REDUNDANCY = 4
"""Points beyond the plane-and-modes terms' count before they are the outlier reference."""


@dataclass(frozen=True)
class PlaneFit:
    """g = p00 + p10 X + p01 Y (Eq. 12) and the columns of the seed's Table 3.

    Tilts follow the seed's g = h0 − x tan γ: γx = −atan(p10), γy = −atan(p01).
    """

    p00_mm: float
    p10: float
    p01: float
    r_squared: float
    rmse_mm: float
    sse_mm2: float
    point_count: int

    @property
    def tilt_x_rad(self) -> float:
        """Tilt about the Y axis that makes the surface fall along +X [rad]."""
        return float(-np.arctan(self.p10))

    @property
    def tilt_y_rad(self) -> float:
        """Tilt that makes the surface fall along +Y [rad]."""
        return float(-np.arctan(self.p01))


@dataclass(frozen=True)
class ModalFit:
    """Least-squares amplitudes [mm] of the mean level and each mode's cos/sin components."""

    names: tuple[str, ...]
    amplitudes_mm: np.ndarray
    rmse_mm: float
    point_count: int


def _finite(points: ArrayLike) -> np.ndarray:
    points = np.atleast_2d(np.asarray(points, dtype=float))
    return points[np.isfinite(points).all(axis=1)]


def _finite_weighted(points_mm: ArrayLike, weights: ArrayLike | None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The finite points and their weights (1 where none are given) [mm, 1/mm²]."""
    points = np.atleast_2d(np.asarray(points_mm, dtype=float))
    weight = np.ones(len(points)) if weights is None else np.asarray(weights, dtype=float)
    keep = np.isfinite(points).all(axis=1) & np.isfinite(weight)
    return points[keep], weight[keep]


def fit_plane(points_mm: ArrayLike, weights: ArrayLike | None = None) -> PlaneFit:
    """Least-squares plane through the finite points (N×3 mm); needs three or more.

    With `weights` (e.g. 1/σ² of each height) the plane is the weighted fit; R², RMSE and SSE
    stay the plain statistics of its residuals.
    """
    points, weight = _finite_weighted(points_mm, weights)
    if len(points) < 3:
        raise ValueError(f"a plane needs 3 or more points, got {len(points)}")
    design = np.column_stack([np.ones(len(points)), points[:, 0], points[:, 1]])
    root = np.sqrt(weight)
    coefficients, *_ = np.linalg.lstsq(design * root[:, None], points[:, 2] * root, rcond=None)
    residual = points[:, 2] - design @ coefficients
    sse = float(residual @ residual)
    sst = float(np.sum((points[:, 2] - points[:, 2].mean()) ** 2))
    r_squared = 1.0 - sse / sst if sst > 0 else float("nan")
    return PlaneFit(float(coefficients[0]), float(coefficients[1]), float(coefficients[2]),
                    r_squared, float(np.sqrt(sse / len(points))), sse, len(points))


def fit_modes(points_mm: ArrayLike, radius_mm: float,
              modes: tuple[tuple[int, int], ...] = DEFAULT_MODES,
              weights: ArrayLike | None = None) -> ModalFit:
    """Mean level plus J_m(ξ r/R)/J_m(ξ) · (cos mθ, sin mθ) per mode (cos alone for m = 0);
    weighted by `weights` where given (RMSE stays the plain one)."""
    points, weight = _finite_weighted(points_mm, weights)
    design, names = modal_design(points, radius_mm, modes)
    if len(points) < design.shape[1]:
        raise ValueError(f"{design.shape[1]} modal terms need as many points, got {len(points)}")
    root = np.sqrt(weight)
    amplitudes, *_ = np.linalg.lstsq(design * root[:, None], points[:, 2] * root, rcond=None)
    residual = points[:, 2] - design @ amplitudes
    return ModalFit(tuple(names), amplitudes, float(np.sqrt(np.mean(residual**2))), len(points))


def modal_heights(fit: ModalFit, xy_mm: ArrayLike, radius_mm: float,
                  modes: tuple[tuple[int, int], ...] = DEFAULT_MODES) -> np.ndarray:
    """The fitted modal surface's heights [mm] at world (x, y) [mm] (N×2)."""
    xy = np.atleast_2d(np.asarray(xy_mm, dtype=float))
    design, names = modal_design(np.column_stack([xy, np.zeros(len(xy))]), radius_mm, modes)
    if tuple(names) != tuple(fit.names):
        raise ValueError(f"the fit has the terms {fit.names}, not {tuple(names)}")
    return design @ np.asarray(fit.amplitudes_mm, dtype=float)


def _leave_one_out(design: np.ndarray, heights: np.ndarray, rejected: np.ndarray) -> np.ndarray:
    """|Leave-one-out residual| e / (1 − h) of every point (fit on the points not rejected):
    a point that pulls the fit onto itself (leverage h) cannot hide its error. NaN where
    1 − h < LEVERAGE_FLOOR (the point alone fixes a term) and for rejected points."""
    used = design[~rejected]
    # One thin SVD gives the least-squares fit and the hat matrix's diagonal (the leverages).
    u, singular, vt = np.linalg.svd(used, full_matrices=False)
    kept = singular > singular[0] * max(used.shape) * np.finfo(float).eps   # lstsq's cutoff
    coefficients = vt[kept].T @ ((u[:, kept].T @ heights[~rejected]) / singular[kept])
    leverage = np.ones(len(heights))
    leverage[~rejected] = np.sum(u[:, kept] ** 2, axis=1)
    residual = np.abs(heights - np.nan_to_num(design) @ coefficients)
    judged = 1.0 - leverage >= LEVERAGE_FLOOR
    result = np.full(len(heights), np.nan)
    result[judged] = residual[judged] / (1.0 - leverage[judged])
    return result


def modal_design(points: np.ndarray, radius_mm: float, modes: tuple[tuple[int, int], ...]
                  ) -> tuple[np.ndarray, list[str]]:
    """The modal fit's design matrix (one column per term) at the points (N×2 or N×3 mm: x, y
    are used), and the terms' names."""
    columns, names = [np.ones(len(points))], ["mean"]
    for order, index in modes:
        for label, azimuth in (("cos", 0.0), ("sin", np.pi / 2)):
            if order == 0 and label == "sin":
                continue
            shape = ModeShape(order, index, azimuth / max(order, 1))
            columns.append(shape.height(points[:, 0], points[:, 1], radius_mm))
            names.append(f"{mode_name(order, index)}_{label}" if order else mode_name(order, index))
    return np.column_stack(columns), names


def radial_profile(points_mm: ArrayLike, radius_mm: float, bins: int = 22
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean height per radial bin (the meniscus seen by the line laser): centres, mean, count."""
    points = _finite(points_mm)
    edges = np.linspace(0.0, radius_mm, bins + 1)
    index = np.clip(np.digitize(np.hypot(points[:, 0], points[:, 1]), edges) - 1, 0, bins - 1)
    count = np.bincount(index, minlength=bins)
    total = np.bincount(index, weights=points[:, 2], minlength=bins)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = total / count
    return (edges[:-1] + edges[1:]) / 2, mean, count


def surface_outliers(points_mm: ArrayLike, height_sigma_mm: ArrayLike, radius_mm: float,
                     miss_distance_mm: ArrayLike | None = None,
                     limit_sigma: float = OUTLIER_LIMIT_SIGMA,
                     floor_mm: float = HEIGHT_SIGMA_FLOOR_MM) -> np.ndarray:
    """Mask of the points that are not on this frame's surface (True = rejected).

    A spot whose camera ray misses its beam (Eq. 9) by more than `limit_sigma` of its height σ
    (floored at `floor_mm`) is not on that beam. Of the others, the suspect is the point with
    the largest σ-normalised leave-one-out residual (a point that pulls the fit onto itself
    cannot hide; σ here adds MODEL_ERROR_MM in quadrature, what the models leave of a real
    surface); it is rejected if, with the surface fitted to the others alone, it lies more
    than `limit_sigma` of that σ off, times the others' robust spread (1.4826 × median
    normalised residual) where that exceeds 1; then the next suspect, until one is not. The
    surface is Eq. 12's plane plus the modes (a tilt table's steep plane and a sloshing surface
    alike) where the points over-determine it, the plane alone where they do not or where the
    point would alone fix a modal term. A surface the models only nearly describe (meniscus,
    higher modes) widens the spread and loses no points; a wrong blob, millimetres off, does.
    """
    points = np.atleast_2d(np.asarray(points_mm, dtype=float))
    measured = np.maximum(np.asarray(height_sigma_mm, dtype=float), floor_mm)
    rejected = ~np.isfinite(points).all(axis=1) | ~np.isfinite(measured)
    if miss_distance_mm is not None:
        miss = np.nan_to_num(np.asarray(miss_distance_mm, dtype=float), nan=0.0)
        rejected |= miss > limit_sigma * measured
    # Off the surface by what the models leave undescribed, too (sloshing beyond three modes).
    sigma = np.hypot(measured, MODEL_ERROR_MM)
    plane = np.column_stack([np.ones(len(points)), points[:, :2]])
    # Plane and modes together: a tilt table's steep plane or a sloshing surface alike.
    surface = np.column_stack([plane, modal_design(points, radius_mm, DEFAULT_MODES)[0][:, 1:]])
    def judged(excluded: np.ndarray) -> np.ndarray:
        """σ-normalised leave-one-out residuals with the points in `excluded` left out: each
        point against the surface fitted to the others (e / (1 − h) is exactly that)."""
        normalised = _leave_one_out(plane, points[:, 2], excluded) / sigma
        if np.sum(~excluded) - 1 >= surface.shape[1] + MODAL_REDUNDANCY:
            # The richer model where it can judge a point; the plane where the point alone
            # would fix one of the modal terms (leverage near 1).
            rich = _leave_one_out(surface, points[:, 2], excluded) / sigma
            normalised = np.where(np.isfinite(rich), rich, normalised)
        normalised[excluded | ~np.isfinite(normalised)] = 0.0
        return normalised

    while np.sum(~rejected) > 4:
        normalised = judged(rejected)
        worst = int(np.argmax(normalised))
        # The suspect is judged against the others' spread with itself left out, so that
        # it cannot widen the spread it is measured by.
        without = rejected.copy()
        without[worst] = True
        others = judged(without)
        spread = max(1.0, 1.4826 * float(np.median(others[~without])))
        if normalised[worst] <= limit_sigma * spread:
            break
        rejected[worst] = True
    return rejected
