"""Surface points from camera rays: laser beams (seed Eq. 9) and the laser plane (Eqs. 10–11)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from sds_model.errors import InputError
from sds_model.rig import Rig

MIN_ANGLE_RAD = np.radians(0.5)
"""Camera rays closer than this to parallel with their beam or plane are flagged, not solved."""
PIXEL_STEP_PX = 0.01
"""Step of the central differences that carry pixel uncertainty into height uncertainty."""


@dataclass(frozen=True)
class BeamPoints:
    """Triangulated beam hits (world mm), the gap between ray and beam, and what was refused."""

    points_mm: np.ndarray        # N×3, NaN where not solved
    miss_distance_mm: np.ndarray  # N, shortest distance between camera ray and beam
    parallel: np.ndarray         # N, True where ray and beam were too close to parallel


def closest_points(origins_a: np.ndarray, directions_a: np.ndarray, origins_b: np.ndarray,
                   directions_b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closest points of line pairs a_i + λ u_i and b_i + s v_i (Eq. 9 in the least-squares sense).

    Returns the points on a, the points on b, and sin of the angle between the lines.
    """
    w = origins_a - origins_b
    a = np.sum(directions_a * directions_a, axis=1)
    b = np.sum(directions_a * directions_b, axis=1)
    c = np.sum(directions_b * directions_b, axis=1)
    d = np.sum(directions_a * w, axis=1)
    e = np.sum(directions_b * w, axis=1)
    denominator = a * c - b * b
    sine = np.sqrt(np.maximum(denominator, 0.0) / (a * c))
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = (b * e - c * d) / denominator
        s = (a * e - b * d) / denominator
    return origins_a + lam[:, None] * directions_a, origins_b + s[:, None] * directions_b, sine


def triangulate_beams(rig: Rig, pixels: ArrayLike, laser_ids: ArrayLike,
                      beam_weight: float = 0.5) -> BeamPoints:
    """Each pixel's camera ray against its diode's beam (Eq. 9).

    The point is the weighted mean of the two closest points: `beam_weight` 1 trusts the beam
    alone (the calibrated beam is usually better known than a ray through a noisy pixel).
    """
    pixels = np.atleast_2d(np.asarray(pixels, dtype=float))
    ids = np.atleast_1d(np.asarray(laser_ids, dtype=int))
    diodes = [rig.diode(int(i)) for i in ids]
    emitters = np.array([d.emitter_mm for d in diodes]).reshape(-1, 3)
    beams = np.array([d.direction for d in diodes]).reshape(-1, 3)
    rays = rig.pixel_rays(pixels)
    centre = np.broadcast_to(rig.camera_position_mm, rays.shape)
    on_ray, on_beam, sine = closest_points(centre, rays, emitters, beams)
    parallel = ~(sine >= np.sin(MIN_ANGLE_RAD))
    points = (1 - beam_weight) * on_ray + beam_weight * on_beam
    miss = np.linalg.norm(on_ray - on_beam, axis=1)
    points[parallel] = np.nan
    miss[parallel] = np.nan
    return BeamPoints(points, miss, parallel)


def triangulate_plane(rig: Rig, pixels: ArrayLike) -> np.ndarray:
    """Camera rays through the pixels against the line laser's plane (Eqs. 10–11), N×3 mm."""
    if rig.line_laser is None:
        raise InputError("the rig has no line laser")
    rays = rig.pixel_rays(np.atleast_2d(np.asarray(pixels, dtype=float)))
    centre, normal = rig.camera_position_mm, rig.line_laser.normal
    facing = rays @ normal
    with np.errstate(divide="ignore", invalid="ignore"):
        distance = ((rig.line_laser.emitter_mm - centre) @ normal) / facing
    distance[~(np.abs(facing) >= np.sin(MIN_ANGLE_RAD)) | ~(distance > 0)] = np.nan
    return centre + distance[:, None] * rays


def _height_sigma(heights: Callable[[np.ndarray], np.ndarray], pixels: ArrayLike,
                  sigma_px: ArrayLike) -> np.ndarray:
    """σ_Z = |∂Z/∂pixel| σ for an isotropic pixel uncertainty, by central differences.

    `heights` gets the N pixels shifted by +x, −x, +y, −y, stacked (4N×2) in one call.
    """
    pixels = np.atleast_2d(np.asarray(pixels, dtype=float))
    steps = PIXEL_STEP_PX * np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    shifted = heights((pixels[None, :, :] + steps[:, None, :]).reshape(-1, 2))
    plus_x, minus_x, plus_y, minus_y = shifted.reshape(4, len(pixels))
    slopes = (plus_x - minus_x, plus_y - minus_y)
    return np.hypot(*slopes) / (2 * PIXEL_STEP_PX) * np.asarray(sigma_px, dtype=float)


def beam_height_sigma(rig: Rig, pixels: ArrayLike, laser_ids: ArrayLike,
                      sigma_px: ArrayLike) -> np.ndarray:
    """Height uncertainty [mm] of beam points from an isotropic pixel uncertainty σ [px]."""
    shifted_ids = np.tile(np.atleast_1d(np.asarray(laser_ids, dtype=int)), 4)
    return _height_sigma(lambda p: triangulate_beams(rig, p, shifted_ids).points_mm[:, 2],
                         pixels, sigma_px)


def plane_height_sigma(rig: Rig, pixels: ArrayLike, sigma_px: ArrayLike) -> np.ndarray:
    """Height uncertainty [mm] of line-laser points from a pixel uncertainty σ [px]."""
    return _height_sigma(lambda p: triangulate_plane(rig, p)[:, 2], pixels, sigma_px)


def beam_points_mm(rig: Rig, laser_id: int, heights_mm: ArrayLike) -> np.ndarray:
    """The diode's beam at surface heights Z (world, mm): its points there (N×3 mm)."""
    diode = rig.diode(laser_id)
    heights = np.asarray(heights_mm, dtype=float)
    if abs(diode.direction[2]) < 1e-9:
        raise InputError(f"diode {laser_id}'s beam is horizontal: it has no height path")
    return diode.point_at((heights - diode.emitter_mm[2]) / diode.direction[2])


def beam_image_path(rig: Rig, laser_id: int, heights_mm: ArrayLike) -> np.ndarray:
    """The diode's spot in the image for surface heights Z (world, mm): its path (N×2 px)."""
    return rig.project(beam_points_mm(rig, laser_id, heights_mm))


def line_image_path(rig: Rig, height_mm: float, samples: int = 400) -> np.ndarray:
    """The line laser's light on a flat surface at height Z [mm], across the container (N×2 px)."""
    if rig.line_laser is None:
        raise InputError("the rig has no line laser")
    normal, emitter = rig.line_laser.normal, rig.line_laser.emitter_mm
    along = np.cross(normal, [0.0, 0.0, 1.0])
    if np.linalg.norm(along) < 1e-9:
        raise InputError("the laser plane is horizontal: it draws no line on a level surface")
    along /= np.linalg.norm(along)
    across = np.cross([0.0, 0.0, 1.0], along)   # horizontal, in the plane's normal direction
    # The point of the line nearest the axis: Z = height, on the plane, along `across`.
    start = np.array([0.0, 0.0, height_mm])
    shift = ((emitter - start) @ normal) / (across @ normal)
    closest = start + shift * across
    radius = rig.container.radius_mm
    half = np.sqrt(max(radius**2 - shift**2, 0.0))
    points = closest + np.linspace(-half, half, samples)[:, None] * along
    return rig.project(points)
