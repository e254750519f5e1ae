"""Where laser light meets the simulated surface: beams, the line laser, wall reflections."""

from __future__ import annotations

import numpy as np
from sds_model.rig import LineLaser

from sds_sim.surface import Surface

BRACKET_STEP_MM = 1.0
"""Sampling step along a ray to bracket its first crossing of the surface (then refined);
finer than any wave the modes make along a ray that is steeper than the surface."""
ROOT_TOLERANCE_MM = 1e-11
ROOT_MAX_ITERATIONS = 100


def ray_surface_points(surface: Surface, origins: np.ndarray, directions: np.ndarray,
                       time_s: float | np.ndarray) -> np.ndarray:
    """First crossing of each ray with h(x, y, t), solved along the ray (N×3 mm), at one time
    [s] or at each ray's own (N: a rolling shutter's rows).

    Exact to ROOT_TOLERANCE_MM: the rays are sampled every BRACKET_STEP_MM through the band the
    surface can occupy, the first sign change of z − h is bracketed and refined by the Illinois
    (modified regula falsi) method. NaN where a ray meets no surface inside the container.
    """
    origins, directions = np.atleast_2d(origins), np.atleast_2d(directions)
    times = np.broadcast_to(np.asarray(time_s, dtype=float), (len(origins),))
    bound = surface.bound_mm() + 1.0
    dz = directions[:, 2]
    downward = dz < -1e-9
    safe_dz = np.where(downward, dz, -1.0)
    near = (origins[:, 2] - bound) / -safe_dz
    far = (origins[:, 2] + bound) / -safe_dz
    steps = int(np.ceil(np.max(far - near) / BRACKET_STEP_MM)) + 1 if downward.any() else 2
    fraction = np.linspace(0.0, 1.0, steps)
    distances = near[:, None] + (far - near)[:, None] * fraction[None, :]
    points = origins[:, None, :] + distances[..., None] * directions[:, None, :]
    gap = points[..., 2] - surface.height(points[..., 0], points[..., 1], times[:, None])
    below = gap <= 0
    first = np.argmax(below, axis=1)
    found = below[np.arange(len(first)), first] & (first > 0) & downward
    rows = np.flatnonzero(found)
    low = distances[rows, first[rows] - 1]
    high = distances[rows, first[rows]]
    f_low = gap[rows, first[rows] - 1]
    f_high = gap[rows, first[rows]]
    o, d, t = origins[rows], directions[rows], times[rows]
    for _ in range(ROOT_MAX_ITERATIONS):
        guess = high - f_high * (high - low) / (f_high - f_low)
        point = o + guess[:, None] * d
        f_guess = point[:, 2] - surface.height(point[:, 0], point[:, 1], t)
        above = f_guess > 0
        # Illinois: halve the value kept at the end that did not move.
        f_high = np.where(above, f_high * 0.5, f_guess)
        high = np.where(above, high, guess)
        f_low = np.where(above, f_guess, f_low * 0.5)
        low = np.where(above, guess, low)
        if np.all(high - low < ROOT_TOLERANCE_MM) or np.all(np.abs(f_guess) < ROOT_TOLERANCE_MM):
            break
    result = np.full(origins.shape, np.nan)
    result[rows] = o + guess[:, None] * d
    outside = np.hypot(result[:, 0], result[:, 1]) > surface.radius_mm
    result[outside] = np.nan
    return result


def line_laser_rays(line: LineLaser, radius_mm: float, count: int) -> np.ndarray:
    """Unit directions (count×3) fanning in the laser plane across the container's width."""
    to_centre = -line.emitter_mm
    down = to_centre - (to_centre @ line.normal) * line.normal
    down /= np.linalg.norm(down)
    along = np.cross(line.normal, down)
    half = np.arctan2(radius_mm * 1.05, np.linalg.norm(to_centre))
    angles = np.linspace(-half, half, count)
    return np.cos(angles)[:, None] * down + np.sin(angles)[:, None] * along


def wall_reflections(surface: Surface, points: np.ndarray, directions: np.ndarray,
                     time_s: float | np.ndarray, wall_height_mm: float) -> np.ndarray:
    """Where each beam, mirrored at the surface, meets the cylinder wall (N×3 mm); NaN if above it
    (at one time [s] or at each beam's own).

    These are the secondary reflections the seed saw on the container wall (its Fig. 9).
    """
    result = np.full(points.shape, np.nan)
    valid = np.isfinite(points).all(axis=1)
    if not valid.any():
        return result
    p, d = points[valid], directions[valid]
    times = np.broadcast_to(np.asarray(time_s, dtype=float), (len(points),))[valid]
    n = surface.normal(p[:, 0], p[:, 1], times)
    r = d - 2 * np.sum(d * n, axis=1, keepdims=True) * n
    a = r[:, 0] ** 2 + r[:, 1] ** 2
    b = 2 * (p[:, 0] * r[:, 0] + p[:, 1] * r[:, 1])
    c = p[:, 0] ** 2 + p[:, 1] ** 2 - surface.radius_mm**2
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a)
    hit = p + s[:, None] * r
    hit[~(hit[:, 2] < wall_height_mm) | ~(r[:, 2] > 0)] = np.nan
    result[valid] = hit
    return result
