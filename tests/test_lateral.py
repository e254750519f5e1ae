"""The side camera (issue 36): its view file, its pose from the checkerboard, the wall profile,
its clock link, the top surface at the wall, and `sds process --lateral` end to end.

The simulator draws the side view from the same surface as the top view with a side camera
that differs from its view file (intrinsics off by one σ, the board off its stated place, its
clock started elsewhere and drifting); the checks compare with that truth.
"""

from __future__ import annotations

import csv
import json
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from sds_lateral.board import BoardError, camera_pose_from_boards
from sds_lateral.clock import ClockError, link_lateral_clock
from sds_lateral.comparison import top_surface_series
from sds_lateral.view import LateralViewError, load_lateral_view
from sds_lateral.wall_profile import WallProfiler
from sds_model.rig import load_rig
from sds_recon.surface_fit import DEFAULT_MODES, fit_modes, modal_design
from sds_sim.lateral import LateralRenderer
from sds_sim.scenario import LateralSpec, load_scenario
from sds_sim.simulate import simulate
from sds_workflows.lateral import LateralInput
from sds_workflows.process import process_video

REPO = Path(__file__).resolve().parents[1]
VIEW_FILE = REPO / "config" / "lateral" / "stelium_side.yaml"
KICK = REPO / "config" / "scenarios" / "ground_kick.yaml"


def side_scenario(seconds: float, **spec: object):
    """The 1 g kick with a side camera off its view file as `spec` says."""
    scenario = load_scenario(KICK, {"duration_s": seconds})
    lateral = replace(LateralSpec(view_file=str(VIEW_FILE)), **spec)
    return replace(scenario, lateral=lateral)


@pytest.fixture(scope="module")
def renderer() -> LateralRenderer:
    return LateralRenderer(side_scenario(1.2, intrinsics_off_sigmas=1.0,
                                         board_offset_mm=(0.06, -0.1, 0.08),
                                         position_mm=(3.0, -405.0, -18.0), roll_deg=0.7))


def test_the_view_file_reads_and_bad_ones_name_the_field(tmp_path: Path) -> None:
    view = load_lateral_view(VIEW_FILE)
    assert view.fps == 125.0 and view.camera.width_px == 512 and len(view.boards) == 2
    corners = view.boards[0].corners_mm()
    assert corners.shape == (54, 3)
    assert np.allclose(corners[1] - corners[0], [7.0, 0.0, 0.0])     # along a row: +X
    assert np.allclose(corners[9] - corners[0], [0.0, 0.0, -7.0])    # down a column: −Z
    text = VIEW_FILE.read_text().replace("../cameras/", str(REPO / "config" / "cameras") + "/")
    cases = {"led_roi_px: [452, 28, 32, 32]": ("led_roi_px: [500, 28, 32, 32]", "led_roi_px"),
             "fps: 125.0": ("fps: -1", "fps"),
             "    placement_sigma_mm: 0.1       #": (
                 "    colour: red\n    placement_sigma_mm: 0.1  #", "boards[0]: unknown keys")}
    for original, (changed, named) in cases.items():
        path = tmp_path / "view.yaml"
        path.write_text(text.replace(original, changed))
        with pytest.raises(LateralViewError, match=re.escape(named)) as error:
            load_lateral_view(path)
        assert str(path) in str(error.value) and "\n" not in str(error.value)


def test_the_boards_place_the_camera_within_its_sigma(renderer: LateralRenderer) -> None:
    board = camera_pose_from_boards(renderer.board_images(), renderer.view.boards,
                                    renderer.view.camera, renderer.view.camera_sigma)
    assert board.reprojection_rms_px < 0.3
    # The camera file is off by one σ in every intrinsic and the board off its stated place:
    # the centre lands off the truth, and its σ must say by about how much.
    error = board.camera_position_mm - renderer.centre_mm
    assert np.all(np.abs(error) < 3 * board.position_sigma_mm + 0.05), (error,
                                                                          board.position_sigma_mm)
    # Told the true intrinsics and the board's true place, the pose is right to a tenth of mm.
    exact = camera_pose_from_boards(renderer.board_images(), renderer.boards, renderer.camera)
    assert np.linalg.norm(exact.camera_position_mm - renderer.centre_mm) < 0.2
    rotation_error = exact.world_to_camera.rotation @ renderer.pose.rotation.T
    assert np.degrees(np.arccos(np.clip((np.trace(rotation_error) - 1) / 2, -1, 1))) < 0.02


def test_an_image_without_the_board_is_refused(renderer: LateralRenderer) -> None:
    frame, _ = renderer.render(0)
    images = renderer.board_images()
    with pytest.raises(BoardError, match="board image 2: no checkerboard of 9x6 inner corners"):
        camera_pose_from_boards([images[0], frame], renderer.view.boards, renderer.view.camera)
    with pytest.raises(BoardError, match="1 board images for the view file's 2"):
        camera_pose_from_boards(images[:1], renderer.view.boards, renderer.view.camera)


def test_the_wall_profile_follows_the_true_contact_line(renderer: LateralRenderer) -> None:
    board = camera_pose_from_boards(renderer.board_images(), renderer.view.boards,
                                    renderer.view.camera, renderer.view.camera_sigma)
    profiler = WallProfiler(renderer.view.camera, board.world_to_camera, renderer.radius_mm,
                            board)
    scenario, radius = renderer.scenario, renderer.radius_mm
    errors, row_errors, pose_sigma = [], [], []
    for index in (0, 80, 95, 110, 125, 140):       # flat, then after the kick at 0.5 s
        frame, truth = renderer.render(index)
        profile = profiler.profile(frame)
        assert profile.valid.mean() > 0.99
        azimuth = profile.azimuth_rad[profile.valid]
        true_mm = scenario.surface_at(truth.time_s).height(
            radius * np.cos(azimuth), radius * np.sin(azimuth), truth.time_s)
        errors.append(profile.wall_mm[profile.valid, 2] - true_mm)
        row_errors.append(profile.edge_row_px[profile.valid]
                          - truth.edge_row_px[profile.column_px[profile.valid].astype(int)])
        pose_sigma.append(profile.pose_sigma_z_mm[profile.valid])
    error, rows, sigma = (np.concatenate(v) for v in (errors, row_errors, pose_sigma))
    assert np.sqrt(np.mean(rows**2)) < 0.1          # the edge, in the image: sub-pixel
    assert np.sqrt(np.mean(error**2)) < 0.3         # the goal, on a camera off its file
    # What is left is the pose's error, the same in every frame: its σ covers it.
    assert abs(np.mean(error)) < 3 * np.sqrt(np.mean(sigma**2))


def test_the_clock_paths_combine_by_their_sigma() -> None:
    true_offset = -0.1371
    led_on = 0.3
    top_period, side_period = 1 / 30, 1 / 125
    # The first frames showing the LED on, on each camera's own clock.
    top_on = [np.ceil(led_on / top_period) * top_period]
    side_on = [np.ceil((led_on - true_offset) / side_period) * side_period]
    direct = link_lateral_clock(side_on, side_period, top_on, top_period)
    assert direct.sigma_s == pytest.approx(np.hypot(top_period, side_period) / np.sqrt(12))
    assert abs(direct.offset_s - true_offset) < top_period / 2 + side_period / 2
    device_offset = 1.234      # device time = top time − 1.234 s
    both = link_lateral_clock(side_on, side_period, top_on, top_period, [led_on - device_offset],
                              (device_offset, 0.0003))
    assert len(both.paths) == 2 and both.disagreement_sigmas is not None
    via = both.paths[1]
    assert abs(via.offset_s - true_offset) < side_period / 2 + 1e-9
    assert both.sigma_s < via.sigma_s < direct.sigma_s
    with pytest.raises(ClockError, match="led_roi_px"):
        link_lateral_clock([], side_period, top_on, top_period)


def test_the_top_surface_at_the_wall_and_its_sigma_are_honest() -> None:
    rng = np.random.default_rng(5)
    radius, frames, sigma_mm = 55.0, 400, 0.08
    ring = np.array([[r * np.cos(a), r * np.sin(a)] for r in (18.0, 32.0, 45.0)
                     for a in np.linspace(0, 2 * np.pi, 7, endpoint=False)])
    design, names = modal_design(ring, radius, DEFAULT_MODES)
    times = np.arange(frames) / 30.0
    fits_rows, point_rows = [], []
    for k, t in enumerate(times):
        heights = design @ _truth_at(t) + rng.normal(0.0, sigma_mm, len(ring))
        fit = fit_modes(np.column_stack([ring, heights]), radius)
        fits_rows.append((k, t, *fit.amplitudes_mm))
        point_rows += [(k, t, i, x, y, z, sigma_mm, 0)
                       for i, ((x, y), z) in enumerate(zip(ring, heights, strict=True))]
    fits = np.array(fits_rows, dtype=[("frame", int), ("t_s", float)]
                    + [(f"{n}_mm", float) for n in names])
    points = np.array(point_rows, dtype=[("frame", int), ("t_s", float), ("laser_id", int),
                                         ("X_mm", float), ("Y_mm", float), ("Z_mm", float),
                                         ("sigma_Z_mm", float), ("rejected", int)])
    series = top_surface_series(fits, points, radius)
    azimuth = np.linspace(-2.6, -0.5, 40)
    wall = radius * np.column_stack([np.cos(azimuth), np.sin(azimuth)])
    wall_design, _ = modal_design(wall, radius, DEFAULT_MODES)
    pulls, between, rates = [], [], []
    for k in range(20, frames - 20, 3):
        height, sigma, _ = series.wall(times[k], azimuth)
        pulls.append((height - wall_design @ _truth_at(times[k])) / sigma)
        # Between two top frames the spline follows the wave (a straight line would cut its
        # crests by 5 % of 3 mm): no worse than at the frames.
        middle = times[k] + 0.5 / 30
        height, sigma, rate = series.wall(middle, azimuth)
        between.append((height - wall_design @ _truth_at(middle)) / sigma)
        true_rate = wall_design @ (_truth_at(middle + 1e-4) - _truth_at(middle - 1e-4)) / 2e-4
        rates.append((rate, true_rate))
    pull, middle_pull = np.concatenate(pulls), np.concatenate(between)
    assert 0.8 < np.sqrt(np.mean(pull**2)) < 1.2, np.sqrt(np.mean(pull**2))
    assert np.sqrt(np.mean(middle_pull**2)) < 1.2
    # The rate scales the clock's σ into mm: a spline through noisy amplitudes differentiates
    # their noise too (here 14 %), which is plenty for a σ.
    rate, true_rate = (np.concatenate(v) for v in zip(*rates, strict=True))
    assert np.sqrt(np.mean((rate - true_rate) ** 2)) < 0.2 * np.sqrt(np.mean(true_rate**2))
    assert np.all(np.isnan(series.wall(times[-1] + 1.0, azimuth)[0]))


def _truth_at(time_s: float) -> np.ndarray:
    return np.array([0.1, 3 * np.sin(2 * np.pi * 2.8 * time_s),
                     0.5 * np.cos(2 * np.pi * 2.8 * time_s), 0.4 * np.sin(5 * time_s),
                     0.1 * np.cos(5 * time_s), 0.3 * np.sin(4.2 * time_s)])


SDS = str(Path(sys.executable).with_name("sds"))
TOP_SCALE = 0.25


@pytest.fixture(scope="module")
def side_run(tmp_path_factory: pytest.TempPathFactory):
    """A 1.4 s kick with both cameras (the top at a quarter of 4K), processed with the side
    camera's video, view file and board image, the top LED's region and the Arduino's log."""
    folder = tmp_path_factory.mktemp("side_run")
    scenario = replace(side_scenario(1.4, intrinsics_off_sigmas=1.0, clock_offset_s=-0.2113,
                                     board_offset_mm=(-0.05, 0.09, -0.07),
                                     position_mm=(-2.0, -396.0, -21.0)),
                       scale=TOP_SCALE)
    simulation = simulate(scenario, folder / "sim", progress=False)
    rig = load_rig(REPO / "config" / "rigs" / "stelium.yaml")
    rig = replace(rig, camera=rig.camera.scaled(TOP_SCALE))
    led = round(220 * TOP_SCALE)
    inputs = LateralInput(simulation.lateral_video, VIEW_FILE, simulation.lateral_boards,
                          (led - 5, led - 5, 10, 10), simulation.sd_log)
    run = process_video(simulation.video, rig, folder / "results", progress=False,
                        lateral=inputs)
    return scenario, simulation, run, folder / "results"


def test_process_writes_the_side_view_its_clock_and_the_check(side_run) -> None:
    scenario, simulation, run, results = side_run
    side = run.lateral
    assert side is not None
    truth = [row for row in csv.DictReader((simulation.directory / "truth" /
                                            "lateral.csv").open())]
    frames = list(csv.DictReader((results / "lateral.csv").open()))
    assert len(frames) == len(truth) == side.frames
    # The clock, by both paths, within a side frame period of the truth, and σ honest.
    error_s = side.clock.offset_s - scenario.lateral.clock_offset_s
    assert len(side.clock.paths) == 2
    assert abs(error_s) < 1 / 125 and abs(error_s) < 3 * side.clock.sigma_s
    for row, true in zip(frames, truth, strict=True):
        assert float(row["t_s"]) == pytest.approx(float(true["time_s"]), abs=1 / 125)
    # The wall profile against the true surface at the wall, at each side frame's true time.
    radius = scenario.rig.container.radius_mm
    errors = []
    for row in csv.DictReader((results / "lateral_profile.csv").open()):
        time_s = float(truth[int(row["frame"])]["time_s"])
        azimuth = np.radians(float(row["azimuth_deg"]))
        errors.append(float(row["Z_mm"]) - scenario.surface_at(time_s).height(
            radius * np.cos(azimuth), radius * np.sin(azimuth), time_s))
    assert len(errors) > 50 * len(frames)
    assert np.sqrt(np.mean(np.square(errors))) < 0.3
    # The check: side − top about its mean, against what both σ predict.
    summary = side.summary
    assert summary.frames > 0.8 * len(frames)
    assert 0.5 < summary.scatter_mm / summary.predicted_mm < 2.0, summary
    assert 0.3 < summary.mean_difference_mm < 1.3    # the 0.8 mm meniscus at the wall
    # The wave's own timing finds what the LED clock missed, within its σ.
    wave_error_s = side.clock.offset_s + summary.wave_shift_s - scenario.lateral.clock_offset_s
    assert abs(wave_error_s) < 3 * summary.wave_shift_sigma_s + 2e-4, (wave_error_s, summary)
    assert summary.wave_shift_sigma_s < side.clock.sigma_s
    assert 0.5 < summary.aligned_scatter_mm / summary.aligned_predicted_mm < 2.0, summary
    # Both cameras told the true rig at 1 g: no tilt between the two surfaces beyond 0.1°.
    assert max(abs(v) for v in summary.tilt_deg) < 0.1, summary
    report = (results / "report.html").read_text()
    assert "Side camera" in report and "side clock" in report
    analysis = json.loads((results / "analysis.json").read_text())
    assert analysis["lateral"]["comparison"]["frames"] == summary.frames
    assert "modes" in analysis       # the sloshing analysis is still there


def test_a_bad_side_input_fails_before_any_work_in_one_line(side_run, tmp_path: Path) -> None:
    _, simulation, _, _ = side_run
    rig = str(REPO / "config" / "rigs" / "stelium.yaml")
    base = ["process", "--video", str(simulation.video), "--rig", rig, "--out"]
    done = subprocess.run([SDS, *base, str(tmp_path / "a"), "--lateral",
                           str(simulation.lateral_video)], capture_output=True, text=True,
                          timeout=120)
    one_line_error(done, "--lateral needs --lateral-view and --lateral-board")
    no_board = tmp_path / "no_board.png"
    cv2.imwrite(str(no_board), np.full((512, 512), 128, np.uint8))
    done = subprocess.run([SDS, *base, str(tmp_path / "b"), "--lateral",
                           str(simulation.lateral_video), "--lateral-view", str(VIEW_FILE),
                           "--lateral-board", str(simulation.lateral_boards[0]), str(no_board),
                           "--led-roi", "45", "45", "20", "20"], capture_output=True, text=True,
                          timeout=120)
    one_line_error(done, "no_board.png: board image 2: no checkerboard of 9x6 inner corners")
    assert not (tmp_path / "b").exists()


def test_a_side_camera_that_fails_keeps_the_top_results(side_run, tmp_path: Path) -> None:
    """The side view's LED region pointed at the dark base: no clock link, so no comparison,
    said on the summary line; the top camera's results are written whole all the same."""
    _, simulation, _, _ = side_run
    view = VIEW_FILE.read_text().replace("../cameras/", str(REPO / "config" / "cameras") + "/")
    dark_view = tmp_path / "dark_led.yaml"
    dark_view.write_text(view.replace("led_roi_px: [452, 28, 32, 32]",
                                      "led_roi_px: [240, 480, 32, 32]"))
    rig = load_rig(REPO / "config" / "rigs" / "stelium.yaml")
    rig = replace(rig, camera=rig.camera.scaled(TOP_SCALE))
    run = process_video(simulation.video, rig, tmp_path / "results", progress=False,
                        lateral=LateralInput(simulation.lateral_video, dark_view,
                                             simulation.lateral_boards, None,
                                             simulation.sd_log))
    assert run.incomplete and run.lateral is None
    assert "SIDE CAMERA NOT COMPARED: no LED switch-on seen by the side camera" in run.summary()
    assert (tmp_path / "results" / "fits.csv").is_file()
    assert not (tmp_path / "results" / "lateral.csv").exists()


def one_line_error(done: subprocess.CompletedProcess, text: str) -> None:
    assert done.returncode == 2, done.stdout + done.stderr
    assert text in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr
