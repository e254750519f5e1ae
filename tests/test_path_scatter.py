"""A run's own check of its spots' σ: their scatter across their beams' paths
(sds_tracker.path_scatter)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sds_model.rig import load_rig
from sds_recon.triangulation import beam_image_path
from sds_tracker.path_scatter import MIN_FRAMES, PathScatter, across_path_px

RIG_PATH = Path(__file__).resolve().parents[1] / "config" / "rigs" / "stelium.yaml"


def test_the_offset_from_a_path_is_signed_by_its_side_and_taken_from_its_nearest_segment(
        ) -> None:
    path = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])   # along +x, then along +y
    points = np.array([[5.0, 2.0], [5.0, -1.0], [12.0, 5.0], [9.0, 6.0], [13.0, 0.0]])
    np.testing.assert_allclose(across_path_px(path, points), [2.0, -1.0, -2.0, 1.0, 3.0])


def scattered_spots(stated_sigma_px: float, frames: int, seed: int) -> PathScatter:
    """Twenty diodes, each on a curved path of its own with an offset of its own (a rig file's
    error), moving along it by tens of px from frame to frame (a sloshing surface) and by
    0.1 px across it (its measurement's error), each spot stating `stated_sigma_px`."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, 15)[:, None]
    paths = {k: np.hstack([100.0 * k + 50.0 * t, 400.0 * t + 30.0 * t**2]) for k in range(20)}
    offsets = rng.normal(0.0, 0.5, 20)
    scatter = PathScatter(paths)
    for _ in range(frames):
        points = []
        for k in paths:
            along = rng.uniform(0.2, 0.8)
            at = np.array([100.0 * k + 50.0 * along, 400.0 * along + 30.0 * along**2])
            tangent = np.array([50.0, 400.0 + 60.0 * along])
            normal = np.array([-tangent[1], tangent[0]]) / np.hypot(*tangent)
            points.append(at + (offsets[k] + rng.normal(0.0, 0.1)) * normal)
        scatter.add(np.arange(20), np.array(points), np.full(20, stated_sigma_px))
    return scatter


@pytest.mark.parametrize(("stated_sigma_px", "expected"), [(0.1, 1.0), (0.2, 0.5),
                                                             (0.05, 2.0)])
def test_the_check_is_the_scatter_across_the_paths_over_the_stated_sigma(
        stated_sigma_px: float, expected: float) -> None:
    """Spots moving far along their paths, scattering 0.1 px across them about offsets of
    their own: the check is 0.1 px over the stated σ, whatever the motion and the offsets.
    2000 measurements: its own spread is about 1.6 % (1/√(2·1980)); bound 5 %."""
    check = scattered_spots(stated_sigma_px, 100, seed=1).check()
    assert check is not None and check.spots == 20 and check.measurements == 2000
    assert check.scatter_over_sigma == pytest.approx(expected, rel=0.05)
    verdict = {1.0: "the σ are honest", 0.5: "the σ are too long", 2.0: "the σ are too short"}
    assert verdict[expected] in check.line()


def test_a_spot_measured_in_too_few_frames_is_left_out_and_none_gives_no_check() -> None:
    assert scattered_spots(0.1, MIN_FRAMES - 1, seed=2).check() is None
    scatter = scattered_spots(0.1, MIN_FRAMES, seed=3)
    assert scatter.check() is not None
    scatter.add(np.array([99, 0]), np.array([[0.0, 0.0], [np.nan, 1.0]]), np.array([0.1, 0.1]))
    check = scatter.check()   # a diode without a path, a spot without a position: not counted
    assert check is not None and check.measurements == 20 * MIN_FRAMES


def test_a_rigs_paths_span_its_container_so_a_spot_far_from_its_rest_is_on_its_path() -> None:
    """A spot 120 mm above the fill level (beyond the default tracker's ±40 mm, as a run
    tracked with a wider span measures it) is on its path: its offset is the path's own
    polyline error (none here: each vertical beam lies in a plane through the camera's
    axis, so even the fisheye draws it straight), not its distance along the path from a
    path that ends at 40 mm (tens of px)."""
    rig = load_rig(RIG_PATH)
    scatter = PathScatter.for_rig(rig)
    heights_mm = np.array([-45.0, -10.0, 0.0, 37.0, 120.0, 145.0])
    for diode in rig.tracked_diodes:
        spots = beam_image_path(rig, diode.laser_id, heights_mm)
        path = scatter.paths_px[scatter.rows[diode.laser_id]]
        np.testing.assert_allclose(across_path_px(path, spots), 0.0, atol=1e-6)
    short_path = beam_image_path(rig, rig.tracked_diodes[0].laser_id, np.linspace(-40, 40, 15))
    far_spot = beam_image_path(rig, rig.tracked_diodes[0].laser_id, [120.0])
    assert abs(across_path_px(short_path, far_spot)[0]) > 10.0


def test_a_paths_points_the_camera_does_not_see_are_left_out() -> None:
    """A beam whose path leaves the camera's field at the container's rim (NaN there, as on
    a rig as built) still checks its spots; a path the camera does not see checks none."""
    path = np.array([[0.0, 0.0], [0.0, 10.0], [0.0, 20.0], [np.nan, np.nan]])
    scatter = PathScatter({1: path, 2: np.full((4, 2), np.nan)})
    rng = np.random.default_rng(4)
    for _ in range(MIN_FRAMES * 4):
        scatter.add(np.array([1, 2]), np.array([[rng.normal(0.5, 0.1), 15.0], [3.0, 3.0]]),
                    np.array([0.1, 0.1]))
    check = scatter.check()
    assert check is not None and check.spots == 1 and np.isfinite(check.scatter_over_sigma)
