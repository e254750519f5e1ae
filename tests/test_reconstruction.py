"""Triangulation, beam calibration and surface fits against exact geometry and the simulator."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from sds_model.mode_theory import ModeShape
from sds_model.rig import LaserDiode, Rig, load_rig
from sds_recon.calibration.lasers import (
    KnownSurface,
    calibrate_beams,
    calibrate_line_plane,
    fit_plane_robust,
)
from sds_recon.reconstruction import SurfacePoints, fit_surface
from sds_recon.surface_fit import fit_modes, fit_plane, radial_profile
from sds_recon.triangulation import (
    beam_height_sigma,
    beam_image_path,
    triangulate_beams,
    triangulate_plane,
)
from sds_sim.optics import line_laser_rays, ray_surface_points
from sds_sim.surface import ModeMotion, Surface

TILTS_DEG = np.arange(0, 36, 5)


@pytest.fixture(scope="module")
def rig(repo: Path) -> Rig:
    return load_rig(repo / "config" / "rigs" / "stelium.yaml")


def tilted_beams(rig: Rig, max_tilt_deg: float, seed: int) -> Rig:
    """The rig with every beam leaning by up to `max_tilt_deg` (manufacturing errors)."""
    rng = np.random.default_rng(seed)
    diodes = []
    for diode in rig.diodes:
        lean = np.radians(rng.uniform(0, max_tilt_deg))
        azimuth = rng.uniform(0, 2 * np.pi)
        direction = np.array([np.sin(lean) * np.cos(azimuth), np.sin(lean) * np.sin(azimuth),
                              -np.cos(lean)])
        diodes.append(LaserDiode(diode.laser_id, diode.ring, diode.emitter_mm, direction))
    return replace(rig, diodes=tuple(diodes))


def observe(rig: Rig, surface: Surface) -> tuple[np.ndarray, np.ndarray]:
    """True beam hits on a surface and their pixels, through the simulator's optics."""
    emitters = np.array([d.emitter_mm for d in rig.diodes])
    directions = np.array([d.direction for d in rig.diodes])
    points = ray_surface_points(surface, emitters, directions, 0.0)
    return points, rig.project(points)


def plane(tilt_x_deg: float = 0.0, tilt_y_deg: float = 0.0, offset: float = 0.0) -> Surface:
    return Surface(55.0, (), np.radians(tilt_x_deg), np.radians(tilt_y_deg), offset)


def test_exact_geometry_comes_back_to_1e_9(rig: Rig) -> None:
    leaning = tilted_beams(rig, 2.0, seed=1)
    rng = np.random.default_rng(2)
    ids = np.array([d.laser_id for d in leaning.diodes] * 5)
    heights = rng.uniform(-30, 30, len(ids))
    truth = np.array([leaning.diode(i).point_at((h - 170.0) / leaning.diode(i).direction[2])
                      for i, h in zip(ids, heights, strict=True)])
    result = triangulate_beams(leaning, leaning.project(truth), ids)
    assert np.max(np.abs(result.points_mm - truth)) < 1e-9
    assert np.max(result.miss_distance_mm) < 1e-9 and not result.parallel.any()
    line = leaning.line_laser
    down = -np.cross(line.normal, [0.0, 1.0, 0.0])   # in the plane, towards the liquid
    points = line.emitter_mm + rng.uniform(150, 200, (50, 1)) * down / np.linalg.norm(down) \
        + rng.uniform(-40, 40, (50, 1)) * np.array([0.0, 1.0, 0.0])
    assert np.allclose((points - line.emitter_mm) @ line.normal, 0, atol=1e-12)
    assert np.max(np.abs(triangulate_plane(leaning, leaning.project(points)) - points)) < 1e-9


def test_a_ray_along_its_beam_is_flagged_not_solved(rig: Rig) -> None:
    diode = LaserDiode(99, 0, rig.camera_position_mm.copy(), np.array([0, 0, -1.0]))
    odd = replace(rig, diodes=(*rig.diodes, diode))
    centre = odd.project([[0.0, 0.0, 0.0]])
    result = triangulate_beams(odd, centre, [99])
    assert result.parallel[0] and np.isnan(result.points_mm).all()


def test_image_paths_map_back_to_their_heights(rig: Rig) -> None:
    heights = np.linspace(-40, 60, 11)
    for diode in rig.diodes:
        path = beam_image_path(rig, diode.laser_id, heights)
        back = triangulate_beams(rig, path, [diode.laser_id] * len(heights)).points_mm[:, 2]
        assert np.max(np.abs(back - heights)) < 1e-9


def test_height_uncertainty_matches_monte_carlo(rig: Rig) -> None:
    _, pixels = observe(rig, plane(10.0))
    ids = [d.laser_id for d in rig.diodes]
    predicted = beam_height_sigma(rig, pixels, ids, 0.1)
    rng = np.random.default_rng(3)
    trials = np.array([triangulate_beams(rig, pixels + rng.normal(0, 0.1, pixels.shape),
                                         ids).points_mm[:, 2] for _ in range(2000)])
    assert trials.std(axis=0) == pytest.approx(predicted, rel=0.08)
    # Fig. 7's resolution appears again: outer ring about 0.33 mm/px, inner ring about 0.9.
    assert 0.25 < predicted[0] / 0.1 < 0.45 and 0.7 < predicted[-1] / 0.1 < 1.1


def tilt_table(rig: Rig) -> list[Surface]:
    return [plane(a, 0) for a in TILTS_DEG] + [plane(0, a) for a in TILTS_DEG[1:]]


def test_beam_calibration_recovers_leaning_beams(rig: Rig) -> None:
    truth = tilted_beams(rig, 1.5, seed=4)
    ids, pixels, known = [], [], []
    for surface in tilt_table(truth):
        _, observed = observe(truth, surface)
        ids += [d.laser_id for d in truth.diodes]
        pixels.append(observed)
        known += [KnownSurface(0.0, surface.tilt_x_rad, surface.tilt_y_rad)] * len(truth.diodes)
    pixels = np.concatenate(pixels)
    exact = calibrate_beams(rig, ids, pixels, known)
    for fit in exact:
        assert np.linalg.norm(fit.direction - truth.diode(fit.laser_id).direction) < 1e-9
    rng = np.random.default_rng(5)
    noisy = calibrate_beams(rig, ids, pixels + rng.normal(0, 0.1, pixels.shape), known)
    errors = np.array([np.arccos(np.clip(fit.direction @ truth.diode(fit.laser_id).direction,
                                         -1, 1)) for fit in noisy])
    sigmas = np.array([fit.direction_sigma_rad for fit in noisy])
    # Consistent with the propagated uncertainty: no beam beyond 4σ, and the spread near 1σ
    # (an angle error is the length of a 2-D error: its mean is √(π/2) σ ≈ 1.25 σ).
    assert np.all(errors < 4 * sigmas)
    assert 0.6 < np.mean(errors / sigmas) < 2.0
    assert np.degrees(errors.max()) < 0.2


def test_plane_fit_ignores_the_line_on_the_wall() -> None:
    rng = np.random.default_rng(2)
    normal = np.array([0.94, 0.007, 0.348])
    normal /= np.linalg.norm(normal)
    across = np.cross(normal, [0.0, 1.0, 0.0])
    across /= np.linalg.norm(across)
    # Eight lines fanning out by ±6 mm on the plane, 0.01 mm noise; each ends in a few points
    # 3-12 mm off the plane (the line climbing the container's wall).
    points = [np.outer(np.linspace(-50, 50, 60), np.cross(normal, across))
              + (k - 3.5) * 1.7 * across * np.linspace(-1, 1, 60)[:, None] for k in range(8)]
    points = np.concatenate(points) + rng.normal(0, 0.01, (480, 3))
    wall = rng.choice(480, 30, replace=False)
    points[wall] += rng.uniform(3, 12, 30)[:, None] * normal
    fit = fit_plane_robust(points)
    assert np.degrees(np.arccos(abs(fit.normal @ normal))) < 0.05
    assert fit.rejected == 30 and fit.rms_mm < 0.02
    plain = np.linalg.svd(points - points.mean(axis=0))[2][2]
    assert np.degrees(np.arccos(abs(plain @ normal))) > 0.5    # least squares is tipped


def test_line_plane_calibration_recovers_the_plane(rig: Rig) -> None:
    line = rig.line_laser
    rays = line_laser_rays(line, 55.0, 200)
    pixels, known = [], []
    for surface in tilt_table(rig):
        origins = np.repeat(line.emitter_mm[None], len(rays), axis=0)
        points = ray_surface_points(surface, origins, rays, 0.0)
        pixels.append(rig.project(points))
        known += [KnownSurface(0.0, surface.tilt_x_rad, surface.tilt_y_rad)] * len(rays)
    pixels = np.concatenate(pixels)
    result = calibrate_line_plane(rig, pixels, known)
    assert np.linalg.norm(result.normal - line.normal) < 1e-9
    noisy = calibrate_line_plane(rig, pixels + np.random.default_rng(6).normal(
        0, 0.1, pixels.shape), known)
    assert np.degrees(np.arccos(noisy.normal @ line.normal)) < 0.05


@pytest.mark.parametrize("axis", ["x", "y"])
def test_tilt_table_in_the_manner_of_table_3(rig: Rig, axis: str) -> None:
    rng = np.random.default_rng(7)
    ids = [d.laser_id for d in rig.diodes]
    for angle in TILTS_DEG:
        surface = plane(angle, 0) if axis == "x" else plane(0, angle)
        _, pixels = observe(rig, surface)
        points = triangulate_beams(rig, pixels + rng.normal(0, 0.1, pixels.shape), ids).points_mm
        fit = fit_plane(points)
        measured = fit.tilt_x_rad if axis == "x" else fit.tilt_y_rad
        other = fit.tilt_y_rad if axis == "x" else fit.tilt_x_rad
        assert abs(np.degrees(measured) - angle) < 0.1, (axis, angle)
        assert abs(np.degrees(other)) < 0.1
        assert fit.point_count == 20 and fit.rmse_mm < 0.2
        if angle >= 5:
            assert fit.r_squared > 0.999


def test_modal_fit_recovers_mode_amplitudes(rig: Rig) -> None:
    surface = Surface(55.0, (ModeMotion(ModeShape(1, 1, 0.4), 3.0, 2.79, 0.0, np.pi / 2),
                             ModeMotion(ModeShape(1, 2, -1.0), 0.7, 4.97, 0.0, np.pi / 2),
                             ModeMotion(ModeShape(0, 1), 0.4, 4.19, 0.0, np.pi / 2)))
    points, _ = observe(rig, surface)
    fit = fit_modes(points, 55.0)
    expected = {"mean": 0.0,
                "lateral_1_cos": 3.0 * np.cos(0.4), "lateral_1_sin": 3.0 * np.sin(0.4),
                "lateral_2_cos": 0.7 * np.cos(-1.0), "lateral_2_sin": 0.7 * np.sin(-1.0),
                "axisymmetric_1": 0.4}
    assert dict(zip(fit.names, fit.amplitudes_mm, strict=True)) == pytest.approx(expected,
                                                                                abs=1e-9)
    assert fit.rmse_mm < 1e-9


def test_radial_profile_shows_the_meniscus(rig: Rig) -> None:
    surface = Surface(55.0, meniscus_height_mm=1.5, meniscus_length_mm=2.0)
    line = rig.line_laser
    rays = line_laser_rays(line, 55.0, 800)
    points = ray_surface_points(surface, np.repeat(line.emitter_mm[None], 800, axis=0), rays, 0)
    centres, mean, count = radial_profile(points, 55.0, bins=11)
    assert (count > 0).all()
    expected = 1.5 * np.exp(-(55.0 - centres) / 2.0)
    assert mean[:8] == pytest.approx(expected[:8], abs=1e-3)
    assert mean[-1] > 0.3


def test_sds_calibrate_lasers_writes_a_calibrated_rig(rig: Rig, repo: Path,
                                                      tmp_path: Path) -> None:
    truth = tilted_beams(rig, 1.0, seed=8)
    rng = np.random.default_rng(9)
    spot_rows, surface_rows = [], []
    line = rig.line_laser
    rays = line_laser_rays(line, 55.0, 150)
    line_x = np.full((15, rig.camera.height_px), np.nan)
    for frame, surface in enumerate(tilt_table(truth)):
        _, pixels = observe(truth, surface)
        pixels = pixels + rng.normal(0, 0.05, pixels.shape)
        spot_rows += [f"{frame},{d.laser_id},{x},{y}" for d, (x, y) in
                      zip(truth.diodes, pixels, strict=True)]
        surface_rows.append(f"{frame},{np.degrees(surface.tilt_x_rad)},"
                            f"{np.degrees(surface.tilt_y_rad)}")
        hits = ray_surface_points(surface, np.repeat(line.emitter_mm[None], 150, 0), rays, 0.0)
        line_px = truth.project(hits)
        rows = np.arange(int(np.nanmin(line_px[:, 1])) + 1, int(np.nanmax(line_px[:, 1])))
        order = np.argsort(line_px[:, 1])
        line_x[frame, rows] = np.interp(rows, line_px[order, 1], line_px[order, 0])
    (tmp_path / "spots.csv").write_text("frame,laser_id,x_px,y_px\n" + "\n".join(spot_rows))
    (tmp_path / "surfaces.csv").write_text("frame,tilt_x_deg,tilt_y_deg\n" +
                                           "\n".join(surface_rows))
    np.savez(tmp_path / "line.npz", line_x_px=line_x)
    result = subprocess.run(
        [str(Path(sys.executable).with_name("sds")), "calibrate", "lasers", "--rig",
         str(repo / "config" / "rigs" / "stelium.yaml"), "--spots", str(tmp_path / "spots.csv"),
         "--surfaces", str(tmp_path / "surfaces.csv"), "--line", str(tmp_path / "line.npz"),
         "--out", str(tmp_path / "out" / "rig.yaml")],
        capture_output=True, text=True, timeout=120, check=False)
    assert result.returncode == 0, result.stderr
    calibrated = load_rig(tmp_path / "out" / "rig.yaml")
    for diode in calibrated.diodes:
        cosine = diode.direction @ truth.diode(diode.laser_id).direction
        error = np.degrees(np.arccos(np.clip(cosine, -1, 1)))
        assert error < 0.1, diode.laser_id
    cosine = np.clip(calibrated.line_laser.normal @ line.normal, -1, 1)
    assert np.degrees(np.arccos(cosine)) < 0.05
    report = json.loads((tmp_path / "out" / "rig.report.json").read_text())
    assert len(report["beams"]) == 20 and report["surfaces"] == 15
    assert "lean deg" in result.stdout


def test_free_beam_fit_moves_the_emitter_onto_the_beam(rig: Rig) -> None:
    truth = tilted_beams(rig, 1.0, seed=10)
    shifted = replace(truth, diodes=tuple(
        LaserDiode(d.laser_id, d.ring, d.emitter_mm + np.array([0.4, -0.3, 0.0]), d.direction)
        for d in truth.diodes))
    ids, pixels, known = [], [], []
    for surface in tilt_table(shifted):
        _, observed = observe(shifted, surface)
        ids += [d.laser_id for d in shifted.diodes]
        pixels.append(observed)
        known += [KnownSurface(0.0, surface.tilt_x_rad, surface.tilt_y_rad)] * 20
    fits = calibrate_beams(rig, ids, np.concatenate(pixels), known, fit_emitter=True)
    for fit in fits:
        beam = shifted.diode(fit.laser_id)
        assert np.linalg.norm(fit.direction - beam.direction) < 1e-9
        offset = fit.emitter_mm - beam.emitter_mm
        assert np.linalg.norm(np.cross(offset, beam.direction)) < 1e-9   # on the true beam


def _sloshing_points(rng: np.random.Generator, count: int, radius_mm: float) -> np.ndarray:
    """Points on a surface sloshing in its first lateral mode (4 mm), tilted, with noise."""
    radius = radius_mm * np.sqrt(rng.uniform(0, 0.95, count))
    azimuth = rng.uniform(0, 2 * np.pi, count)
    x, y = radius * np.cos(azimuth), radius * np.sin(azimuth)
    shape = ModeShape(1, 1, 0.3)
    z = 0.5 - 0.1 * x + 4.0 * shape.height(x, y, radius_mm) + rng.normal(0, 0.03, count)
    return np.column_stack([x, y, z])


def test_surface_fits_leave_out_a_wrong_point_and_keep_every_sloshing_one() -> None:
    rng = np.random.default_rng(0)
    radius_mm = 75.0
    points = _sloshing_points(rng, 20, radius_mm)
    sigma, miss = np.full(20, 0.03), np.full(20, 0.005)
    truth = fit_surface(SurfacePoints(np.arange(20), points, sigma, miss), radius_mm)
    assert truth.rejected_count == 0            # 4 mm of sloshing is no outlier
    wrong = points.copy()
    wrong[7, 2] += 3.0                          # a reflection taken for the spot
    fits = fit_surface(SurfacePoints(np.arange(20), wrong, sigma, miss), radius_mm)
    assert fits.rejected.tolist() == [k == 7 for k in range(20)]
    clean = fit_modes(np.delete(points, 7, axis=0), radius_mm)
    assert fits.modal is not None and fits.plane is not None
    np.testing.assert_allclose(fits.modal.amplitudes_mm, clean.amplitudes_mm, atol=1e-12)
    plain = fit_modes(wrong, radius_mm)
    assert np.max(np.abs(plain.amplitudes_mm - clean.amplitudes_mm)) > 0.1
    assert fits.plane.point_count == 19
    # a spot whose ray misses its beam by far more than its σ (Eq. 9) is not on that beam
    far = miss.copy()
    far[3] = 0.5
    fits = fit_surface(SurfacePoints(np.arange(20), points, sigma, far), radius_mm)
    assert fits.rejected.tolist() == [k == 3 for k in range(20)]


def test_surface_fits_keep_the_points_a_model_error_spreads_over() -> None:
    radius_mm = 75.0
    for seed in range(5):
        points = _sloshing_points(np.random.default_rng(seed), 200, radius_mm)
        # a meniscus the modes do not contain: 0.8 mm at the wall, decaying over 3 mm
        radius = np.hypot(points[:, 0], points[:, 1])
        points[:, 2] += 0.8 * np.exp(-(radius_mm - radius) / 3.0)
        sigma = np.full(200, 0.03)
        fits = fit_surface(SurfacePoints(np.arange(200), points, sigma, sigma / 5), radius_mm)
        # only points in the steep band by the wall (14 σ off the modes) may go
        assert fits.rejected_count <= 20          # of 200
        assert np.all(radius[fits.rejected] > radius_mm - 6.0)
