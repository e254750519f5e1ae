"""Wall reflections: where a beam mirrored at the liquid's surface lights the wall."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from sds_model.rig import load_rig
from sds_recon.wall_reflection import wall_reflections_mm, wall_reflections_px

RIG = Path(__file__).resolve().parents[1] / "config" / "rigs" / "stelium.yaml"


def tilted_normals(count: int, rng: np.random.Generator, tilt_deg: float) -> np.ndarray:
    """Unit normals up to `tilt_deg` from the vertical, in random directions."""
    tilt = np.radians(rng.uniform(0.0, tilt_deg, count))
    azimuth = rng.uniform(0.0, 2 * np.pi, count)
    return np.c_[np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), np.cos(tilt)]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_reflection_lies_on_the_wall_along_the_ray_from_the_mirrored_emitter(seed: int
                                                                              ) -> None:
    """Independently of the mirrored direction the module computes: the beam's emitter
    mirrored in the surface's tangent plane at the spot, E' = E − 2((E − P)·n)n, sees the
    reflection through the spot, so each hit lies on the wall (radius R), on the ray from E'
    through P beyond P, and below the wall's top."""
    rig = load_rig(RIG)
    rng = np.random.default_rng(seed)
    count = 200
    radius = rig.container.radius_mm
    points = np.c_[rng.uniform(-0.9, 0.9, (count, 2)) * radius / np.sqrt(2),
                   rng.uniform(-3.0, 3.0, count)]
    emitters = points + np.c_[rng.uniform(-40.0, 40.0, (count, 2)),
                              rng.uniform(100.0, 200.0, count)]
    directions = (points - emitters) / np.linalg.norm(points - emitters, axis=1)[:, None]
    normals = tilted_normals(count, rng, 20.0)
    hits = wall_reflections_mm(rig, points, directions, normals)
    seen = np.isfinite(hits).all(axis=1)
    assert seen.sum() > count // 2
    mirrored = emitters - 2 * np.sum((emitters - points) * normals, axis=1)[:, None] * normals
    ray = (points - mirrored) / np.linalg.norm(points - mirrored, axis=1)[:, None]
    along = np.sum((hits - points) * ray, axis=1)
    off_ray = np.linalg.norm(hits - points - along[:, None] * ray, axis=1)
    assert np.all(along[seen] > 0)
    assert np.max(off_ray[seen]) < 1e-9
    assert np.allclose(np.hypot(hits[seen, 0], hits[seen, 1]), radius, atol=1e-9)
    top = rig.container.height_mm - rig.container.fill_height_mm
    assert np.all(hits[seen, 2] < top)
    # The misses: the mirrored ray goes down, or meets the wall's cylinder above its top.
    distance = np.full(count, np.inf)
    for k in np.flatnonzero(~seen):
        if ray[k, 2] <= 0:
            continue
        a, b = ray[k, :2] @ ray[k, :2], 2 * points[k, :2] @ ray[k, :2]
        c = points[k, :2] @ points[k, :2] - radius**2
        distance[k] = (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a)
        assert points[k, 2] + distance[k] * ray[k, 2] >= top


def test_a_reflection_above_the_wall_or_going_down_is_none() -> None:
    """A level surface mirrors a shallow beam up to the wall; a container whose wall is
    lower than where it arrives loses it over the top, and a surface tilted past the beam
    mirrors it down: both NaN."""
    rig = load_rig(RIG)
    point, direction = np.array([[10.0, 0.0, 0.0]]), np.array([[1.0, 0.0, -0.2]])
    direction /= np.linalg.norm(direction)
    level = np.array([[0.0, 0.0, 1.0]])
    assert np.isfinite(wall_reflections_mm(rig, point, direction, level)).all()
    low = replace(rig, container=replace(rig.container,
                                         height_mm=rig.container.fill_height_mm + 1.0))
    assert np.isnan(wall_reflections_mm(low, point, direction, level)).all()
    steep = np.array([[np.sin(0.35), 0.0, np.cos(0.35)]])
    assert np.isnan(wall_reflections_mm(rig, point, direction, steep)).all()


def test_a_reflections_pixel_is_the_cameras_image_of_its_wall_point() -> None:
    """`wall_reflections_px` projects the wall point of each diode's own beam."""
    rig = load_rig(RIG)
    ids = [d.laser_id for d in rig.tracked_diodes]
    points = np.array([rig.diode(i).point_at(-rig.diode(i).emitter_mm[2] /
                                             rig.diode(i).direction[2]) for i in ids])
    normals = tilted_normals(len(ids), np.random.default_rng(4), 3.0)
    pixels = wall_reflections_px(rig, ids, points, normals)
    directions = np.array([rig.diode(i).direction for i in ids])
    hits = wall_reflections_mm(rig, points, directions, normals)
    seen = np.isfinite(hits).all(axis=1)
    assert seen.any()
    assert np.allclose(pixels[seen], rig.project(hits[seen]))
    assert np.isnan(pixels[~seen]).all()
