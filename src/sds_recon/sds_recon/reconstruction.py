"""One frame's surface: tracked pixels to world points (Eqs. 9–11) and their fits (Eq. 12).

The reconstruction node and the offline pipeline (`sds process`) both call these, so a graph
run and an offline run of the same frames give the same points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from sds_model.rig import Rig

from sds_recon.surface_fit import (
    HEIGHT_SIGMA_FLOOR_MM,
    ModalFit,
    PlaneFit,
    fit_modes,
    fit_plane,
    surface_outliers,
)
from sds_recon.triangulation import (
    beam_height_sigma,
    plane_height_sigma,
    triangulate_beams,
    triangulate_plane,
)

LINE_LASER_ID = 65535
"""laser_id of the line laser's points."""
MIN_PLANE_POINTS = 3


@dataclass(frozen=True)
class SurfacePoints:
    """Triangulated points [mm, world], each with its laser, height σ and miss distance [mm], and
    the image row it was measured in (a rolling shutter's rows have their own times)."""

    laser_ids: np.ndarray          # (N,)
    points_mm: np.ndarray          # (N, 3)
    height_sigma_mm: np.ndarray    # (N,)
    miss_distance_mm: np.ndarray   # (N,), NaN for the line laser
    row_px: np.ndarray | None = None   # (N,) the image row each was seen in (None: unknown)


@dataclass(frozen=True)
class SurfaceFits:
    """The plane of Eq. 12 and the modal fit of one frame (None where too few points), and
    which points were left out of both as not on the surface (`surface_outliers`)."""

    plane: PlaneFit | None
    modal: ModalFit | None
    rejected: np.ndarray           # (N,) bool, True = left out

    @property
    def rejected_count(self) -> int:
        """How many points were left out."""
        return int(np.count_nonzero(self.rejected))


def _sigmas(sigma_px: ArrayLike, default_sigma_px: float) -> np.ndarray:
    sigma = np.asarray(sigma_px, dtype=float)
    return np.where(sigma > 0, sigma, default_sigma_px)


def reconstruct_spots(rig: Rig, laser_ids: ArrayLike, pixels: ArrayLike, sigma_px: ArrayLike,
                      beam_weight: float = 0.5, default_sigma_px: float = 0.1) -> SurfacePoints:
    """Eq. 9 for the found spots (finite pixels); unsolvable ones (parallel rays) are left out."""
    ids = np.asarray(laser_ids, dtype=int)
    measured = np.asarray(pixels, dtype=float).reshape(-1, 2)
    found = np.isfinite(measured).all(axis=1)
    ids, seen = ids[found], measured[found]
    sigma = _sigmas(np.asarray(sigma_px, dtype=float)[found], default_sigma_px)
    result = triangulate_beams(rig, seen, ids, beam_weight)
    heights_sigma = beam_height_sigma(rig, seen, ids, sigma)
    keep = np.isfinite(result.points_mm).all(axis=1)
    return SurfacePoints(ids[keep], result.points_mm[keep], heights_sigma[keep],
                         result.miss_distance_mm[keep], seen[keep, 1])


def reconstruct_line(rig: Rig, pixels: ArrayLike, sigma_px: ArrayLike,
                     default_sigma_px: float = 0.1) -> SurfacePoints:
    """Eqs. 10–11 for the line's samples (finite pixels)."""
    samples = np.asarray(pixels, dtype=float).reshape(-1, 2)
    found = np.isfinite(samples).all(axis=1)
    samples = samples[found]
    sigma = _sigmas(np.asarray(sigma_px, dtype=float)[found], default_sigma_px)
    points = triangulate_plane(rig, samples) if len(samples) else np.empty((0, 3))
    heights_sigma = plane_height_sigma(rig, samples, sigma) if len(samples) else np.empty(0)
    keep = np.isfinite(points).all(axis=1)
    return SurfacePoints(np.full(int(keep.sum()), LINE_LASER_ID), points[keep],
                         heights_sigma[keep], np.full(int(keep.sum()), np.nan),
                         samples[keep, 1])


def fit_surface(points: SurfacePoints, radius_mm: float) -> SurfaceFits:
    """Plane (three or more points) and modes (as many points as terms) of one frame, both
    without the points that are not on the surface (one wrong blob cannot move them) and
    weighted by each height's σ (floored at HEIGHT_SIGMA_FLOOR_MM)."""
    rejected = surface_outliers(points.points_mm, points.height_sigma_mm, radius_mm,
                                points.miss_distance_mm)
    kept = points.points_mm[~rejected]
    # Weights 1/σ² with σ floored: points of ordinary quality weigh alike (the seed's plain
    # Eq. 12), a point measured less well (e.g. beside the laser line) weighs less.
    weights = np.maximum(points.height_sigma_mm[~rejected], HEIGHT_SIGMA_FLOOR_MM) ** -2.0
    plane = fit_plane(kept, weights) if len(kept) >= MIN_PLANE_POINTS else None
    try:
        modal = fit_modes(kept, radius_mm, weights=weights)
    except ValueError:
        modal = None   # too few points: no amplitudes rather than invented ones
    return SurfaceFits(plane, modal, rejected)


def frame_points(rig: Rig, laser_ids: ArrayLike, pixels: ArrayLike, sigma_px: ArrayLike,
                 lost: ArrayLike, beam_weight: float = 0.5, default_sigma_px: float = 0.1
                 ) -> SurfacePoints:
    """One frame's spots to its points: lost spots left out, the others triangulated (Eq. 9)."""
    found = ~np.asarray(lost, dtype=bool)
    return reconstruct_spots(rig, np.asarray(laser_ids)[found],
                             np.asarray(pixels, dtype=float).reshape(-1, 2)[found],
                             np.asarray(sigma_px, dtype=float)[found], beam_weight,
                             default_sigma_px)
