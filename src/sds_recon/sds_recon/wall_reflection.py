"""Where a beam, mirrored at the liquid's surface, lights the container's wall (seed Fig. 9a).

The liquid is a mirror: part of each beam's light leaves its spot mirrored about the
surface's normal there and lights the wall where it meets it, below the wall's top. The
camera sees that light as a second, dimmer spot: near the wall (the beam's mirrored path
short) it can lie a few pixels from its own spot and merge with its light.
"""

from __future__ import annotations

import numpy as np
from sds_model.rig import Rig


def wall_reflections_mm(rig: Rig, points_mm: np.ndarray, directions: np.ndarray,
                        normals: np.ndarray) -> np.ndarray:
    """Where each beam (unit `directions`, N×3, towards the liquid) mirrored at its surface
    point (`points_mm`, N×3 world) about the surface's unit normal there (`normals`, N×3,
    up) meets the container's wall (N×3 mm, world); NaN where the mirrored beam goes down,
    or leaves the container above its wall's top (`Container.height_mm` over the floor, the
    world's origin at the fill level)."""
    mirrored = directions - 2 * np.sum(directions * normals, axis=1, keepdims=True) * normals
    # The cylinder x² + y² = R² along the mirrored ray p + s·r, s > 0: the root going out.
    a = mirrored[:, 0] ** 2 + mirrored[:, 1] ** 2
    b = 2 * (points_mm[:, 0] * mirrored[:, 0] + points_mm[:, 1] * mirrored[:, 1])
    c = points_mm[:, 0] ** 2 + points_mm[:, 1] ** 2 - rig.container.radius_mm ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        distance = (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a)
    hits = points_mm + distance[:, None] * mirrored
    top_mm = rig.container.height_mm - rig.container.fill_height_mm
    hits[~((mirrored[:, 2] > 0) & (hits[:, 2] < top_mm))] = np.nan
    return hits


def wall_reflections_px(rig: Rig, laser_ids: list[int], points_mm: np.ndarray,
                        normals: np.ndarray) -> np.ndarray:
    """The image [px] of each diode's wall reflection (`wall_reflections_mm`) from its spot
    on the surface (`points_mm`, N×3 world, `normals` there, N×3): N×2, NaN where it has
    none or the camera does not see it."""
    directions = np.array([rig.diode(i).direction for i in laser_ids]).reshape(-1, 3)
    hits = wall_reflections_mm(rig, points_mm.reshape(-1, 3), directions,
                               normals.reshape(-1, 3))
    pixels = np.full((len(hits), 2), np.nan)
    seen = np.isfinite(hits).all(axis=1)
    if seen.any():
        pixels[seen] = rig.project(hits[seen])
    return pixels
