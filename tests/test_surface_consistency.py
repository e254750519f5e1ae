"""The surface a frame's spots show, and a spot's place on its beam (sds_tracker)."""

from __future__ import annotations

import numpy as np
import pytest
from sds_tracker.spots import beam_points_at
from sds_tracker.surface_consistency import fit_robust_surface


def bulging_points(rng: np.random.Generator, count: int) -> np.ndarray:
    """`count` points [mm] within 45 mm of the axis on a tilted surface with a bulge."""
    radius, angle = 45.0 * np.sqrt(rng.random(count)), rng.uniform(0, 2 * np.pi, count)
    x, y = radius * np.cos(angle), radius * np.sin(angle)
    return np.c_[x, y, 2.0 + 0.3 * x - 0.2 * y + 0.004 * (x**2 + y**2)]


@pytest.mark.parametrize("seed", range(4))
def test_the_surface_is_the_one_most_points_lie_on_whatever_a_few_others_say(seed: int
                                                                           ) -> None:
    """20 points on a tilted surface with a bulge (a 35° still's tilt is 0.7), four of them
    moved 14-40 mm up or down (ghosts on their paths): the fit finds the surface within
    0.01 mm at the right points, and the moved ones by how far they were moved."""
    rng = np.random.default_rng(seed)
    points = bulging_points(rng, 20)
    moved = rng.choice(20, 4, replace=False)
    shift = rng.choice([-1.0, 1.0], 4) * rng.uniform(14.0, 40.0, 4)
    seen = points.copy()
    seen[moved, 2] += shift
    above = fit_robust_surface(seen, 5.0).heights_above_mm(seen)
    right = np.setdiff1d(np.arange(20), moved)
    assert np.abs(above[right]).max() < 0.01, above
    np.testing.assert_allclose(above[moved], shift, atol=0.01)


def test_points_at_one_distance_from_the_axis_give_a_plane_not_a_guess() -> None:
    """Ten points on a circle about the axis do not tell the bulge from the level: the
    plane through them is fitted, and a point off the circle is judged against it."""
    angle = 2 * np.pi * np.arange(10) / 10
    x, y = 30.0 * np.cos(angle), 30.0 * np.sin(angle)
    points = np.c_[x, y, 1.0 + 0.1 * x + 0.2 * y]
    surface = fit_robust_surface(points, 5.0)
    assert np.abs(surface.heights_above_mm(points)).max() < 1e-9
    assert abs(surface.heights_above_mm(np.array([[0.0, 0.0, 1.0]]))[0]) < 1e-6


def test_a_pixel_on_the_path_stands_for_the_beam_point_it_is_the_image_of() -> None:
    """A leaning beam imaged on a bent path (two straight pieces): pixels on the path and
    beside it give the beam's point by the share along their segment; beyond the path's
    ends, its end points."""
    beam = np.c_[np.linspace(0.0, 8.0, 3), np.zeros(3), np.linspace(-40.0, 40.0, 3)]
    path = np.array([[10.0, 10.0], [50.0, 10.0], [50.0, 90.0]])
    pixels = np.array([[30.0, 10.0], [30.0, 12.0], [50.0, 70.0], [0.0, 10.0], [50.0, 99.0]])
    np.testing.assert_allclose(beam_points_at(path, beam, pixels),
                               [[2.0, 0.0, -20.0], [2.0, 0.0, -20.0], [7.0, 0.0, 30.0],
                                beam[0], beam[-1]])
