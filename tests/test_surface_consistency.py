"""The surface a frame's spots show, and a spot's place on its beam (sds_tracker)."""

from __future__ import annotations

import numpy as np
import pytest
from sds_tracker.spots import beam_points_at
from sds_tracker.surface_consistency import fit_robust_surface


def tilted_points(rng: np.random.Generator, count: int) -> np.ndarray:
    """`count` points [mm] within 45 mm of the axis on a tilted plane."""
    radius, angle = 45.0 * np.sqrt(rng.random(count)), rng.uniform(0, 2 * np.pi, count)
    x, y = radius * np.cos(angle), radius * np.sin(angle)
    return np.c_[x, y, 2.0 + 0.3 * x - 0.2 * y]


@pytest.mark.parametrize("seed", range(4))
def test_the_surface_is_the_one_most_points_lie_on_whatever_a_few_others_say(seed: int
                                                                           ) -> None:
    """20 points on a tilted plane (a 35° still's tilt is 0.7), four of them moved 14-40 mm
    up or down (ghosts on their paths): the fit finds the plane within 0.01 mm at the right
    points, and the moved ones by how far they were moved; its normal is the plane's."""
    rng = np.random.default_rng(seed)
    points = tilted_points(rng, 20)
    moved = rng.choice(20, 4, replace=False)
    shift = rng.choice([-1.0, 1.0], 4) * rng.uniform(14.0, 40.0, 4)
    seen = points.copy()
    seen[moved, 2] += shift
    surface = fit_robust_surface(seen, 5.0)
    above = surface.heights_above_mm(seen)
    right = np.setdiff1d(np.arange(20), moved)
    assert np.abs(above[right]).max() < 0.01, above
    np.testing.assert_allclose(above[moved], shift, atol=0.01)
    np.testing.assert_allclose(surface.normal(), np.array([-0.3, 0.2, 1.0]) / np.sqrt(1.13),
                               atol=1e-12)


def test_points_on_one_line_leave_the_tilt_across_it_out_not_a_guess() -> None:
    """Ten points on one line across the container do not tell the tilt across it: the
    least-norm plane through them is level across the line, and a point beside the line
    is judged against that."""
    along = np.linspace(-40.0, 40.0, 10)
    points = np.c_[along, 0.5 * along, 1.0 + 0.1 * along]
    surface = fit_robust_surface(points, 5.0)
    assert np.abs(surface.heights_above_mm(points)).max() < 1e-9
    beside = np.array([[-10.0, 20.0, 1.0]])   # on the perpendicular through the axis
    assert abs(surface.heights_above_mm(beside)[0]) < 1e-6


def test_a_beam_meets_the_plane_where_its_height_above_it_changes_sign() -> None:
    """A leaning beam sampled at 15 heights crosses a tilted plane between two of them: the
    crossing lies on both (linear between the samples, exact for a straight beam); a beam
    that stays above it within its samples meets it nowhere."""
    surface = fit_robust_surface(tilted_points(np.random.default_rng(5), 20), 5.0)
    beam = np.c_[np.linspace(-5.0, 9.0, 15), np.linspace(3.0, -4.0, 15),
                 np.linspace(-40.0, 40.0, 15)]
    crossing = surface.beam_crossing_mm(beam)
    assert abs(surface.heights_above_mm(crossing[None])[0]) < 1e-9
    direction = (beam[-1] - beam[0]) / np.linalg.norm(beam[-1] - beam[0])
    offset = crossing - beam[0]
    assert np.linalg.norm(offset - (offset @ direction) * direction) < 1e-9
    assert np.isnan(surface.beam_crossing_mm(beam + np.array([0.0, 0.0, 100.0]))).all()


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
