"""The side camera in `sds process`: its pose, its clock, the wall profile and the top/side check.

`place_lateral` places the side camera from its checkerboard images (before the top video is
read: a bad input fails at once); `process_lateral` reads the side video once (the LED in its
region, the contact line in every frame), links its clock to the top
camera's (`sds_lateral.clock`: the LED seen by both, and through the Arduino's LED record and
acceleration where a log is given), and compares the top run's modal fits along the wall with
the side's profile. It writes, into the run's folder:
- lateral.csv: one row per side frame: its time on both clocks, the wall points found, the
  side's mean height and the top's at the same points, side − top (mean, RMS), what the
  side's image noise, the top fit's σ and the clock's σ predict for its scatter;
- lateral_profile.csv: one row per side frame and wall point (every PROFILE_STEP_PX-th
  column): azimuth, X, Y, Z of the side's contact line, its height's σ from the image and
  from the camera's pose (one error for the whole run), the top's height, σ and rate of
  change there;
- lateral.json and a "Side camera" section in report.html (analysis.json's `lateral`).
"""

from __future__ import annotations

import csv
import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import cv2
import matplotlib
from sds_model.errors import InputError

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from sds_camera.frame_source import VideoFileSource
from sds_camera.led import LedDetector
from sds_lateral.board import BoardError, BoardPose, camera_pose_from_boards
from sds_lateral.clock import LateralClock, link_lateral_clock
from sds_lateral.comparison import (
    ComparisonSummary,
    FrameComparison,
    summarise,
    top_surface_series,
)
from sds_lateral.view import LateralView, load_lateral_view
from sds_lateral.wall_profile import WallProfile, WallProfiler
from sds_model.rig import Rig
from sds_recon.results import load_results
from sds_sloshing.report import add_report_section
from tqdm import tqdm

from sds_workflows.clock_link import (
    led_rows_on_s,
    link_clocks,
    read_arduino_log,
    video_led_on_s,
)

LATERAL_FILES = ("lateral.csv", "lateral_profile.csv", "lateral.json", "lateral.png")
"""What `process_lateral` writes into a run's folder."""
PROFILE_STEP_PX = 4
"""lateral_profile.csv keeps every this many image columns (about 1 mm along the wall)."""


@dataclass(frozen=True)
class LateralInput:
    """The side camera's video, its view file, its checkerboard images (one per placement in
    the view file); the top camera's LED region (x, y, w, h) and an Arduino log, each
    optional, for the clock link."""

    video: Path
    view_file: Path
    board_images: tuple[Path, ...]
    top_led_roi: tuple[int, int, int, int] | None = None
    arduino_log: Path | None = None


@dataclass(frozen=True)
class LateralSetup:
    """The side camera placed: its inputs, view file, board pose and wall profiler."""

    inputs: LateralInput
    view: LateralView
    board: BoardPose
    profiler: WallProfiler


@dataclass(frozen=True)
class LateralRun:
    """What the side camera gave: its pose, clock, frames read and the comparison."""

    board: BoardPose
    clock: LateralClock
    frames: int
    summary: ComparisonSummary

    def lines(self) -> list[str]:
        """Console lines."""
        position = self.board.camera_position_mm
        return [f"side camera at ({position[0]:.1f}, {position[1]:.1f}, {position[2]:.1f}) mm "
                f"from its board (corners {self.board.reprojection_rms_px:.2f} px RMS), "
                f"{self.frames} frames", self.clock.summary(), self.summary.summary(),
                self.summary.wave_summary(self.clock.sigma_s)]


def _side_frames(video: Path, profiler: WallProfiler, led_roi: tuple[int, int, int, int],
                 progress: bool) -> tuple[list[float], list[WallProfile], list[float], float]:
    """One pass: each frame's time [s, side clock] and profile, the LED's first on-frames."""
    source = VideoFileSource(video)
    detector = LedDetector(led_roi)
    times: list[float] = []
    profiles: list[WallProfile] = []
    led_on: list[float] = []
    try:
        for frame in tqdm(source.frames(channel="gray"), desc="side view", unit="frame",
                          disable=not progress):
            time_s = frame.time_ns * 1e-9
            switch = detector.update(frame.index, frame.image)
            if switch is not None and switch.on:
                led_on.append(time_s)
            times.append(time_s)
            profiles.append(profiler.profile(frame.image))
    finally:
        source.close()
    return times, profiles, led_on, source.nominal_fps


def link_side_clock(setup: LateralSetup, rig: Rig, top_video: Path) -> LateralClock:
    """The side clock's link to the top camera's before any processing (the LED's pass over
    the side video alone): what `sds run` stamps the side frames with."""
    side_on, period = video_led_on_s(setup.inputs.video, setup.view.led_roi_px)
    return _clock(setup.inputs, rig, top_video, side_on, period)


def _clock(inputs: LateralInput, rig: Rig, top_video: Path, side_on_s: list[float],
           side_period_s: float) -> LateralClock:
    """The side clock's link to the top camera's by every path the inputs allow."""
    top_on = top_period = None
    if inputs.top_led_roi is not None:
        top_on, top_period = led_rows_on_s(top_video, rig, inputs.top_led_roi)
    device_on = top_minus_device = None
    if inputs.arduino_log is not None:
        log = read_arduino_log(inputs.arduino_log)
        acceleration = link_clocks(top_video, log, rig, None).acceleration
        if acceleration is not None:
            device_on = log.led_on_s
            top_minus_device = (acceleration.offset_s, acceleration.sigma_s)
    return link_lateral_clock(side_on_s, side_period_s, top_on, top_period, device_on,
                              top_minus_device)


def place_lateral(inputs: LateralInput, rig: Rig) -> LateralSetup:
    """Read the view file and place the side camera from its board images (before any frame
    is read, so that a bad input fails at once); ValueError-family errors name the file. The
    video may be a live camera's device here (`sds run`); `process_lateral` needs a file."""
    view = load_lateral_view(inputs.view_file)
    images = []
    for path in inputs.board_images:
        image = cv2.imread(str(path))
        if image is None:
            raise InputError(f"{path}: not a readable image (the side camera's checkerboard, "
                             "--lateral-board)")
        images.append(image)
    try:
        board = camera_pose_from_boards(images, view.boards, view.camera, view.camera_sigma)
    except BoardError as error:
        names = ", ".join(str(p) for p in inputs.board_images)
        raise BoardError(f"{names}: {error}") from None
    profiler = WallProfiler(view.camera, board.world_to_camera, rig.container.radius_mm, board)
    return LateralSetup(inputs, view, board, profiler)


def process_lateral(setup: LateralSetup, rig: Rig, top_video: Path, out: Path,
                    progress: bool = True, report: Path | None = None,
                    clock: LateralClock | None = None) -> LateralRun:
    """The placed side camera against a processed top run in `out` (its fits and points):
    writes LATERAL_FILES there and a section into the report in `report` (default: `out`).
    `clock`: the link `link_side_clock` measured already (`sds run`), else it is measured
    here."""
    inputs, view, board = setup.inputs, setup.view, setup.board
    if not inputs.video.is_file():
        raise InputError(f"{inputs.video}: no such video (the side camera's, --lateral)")
    times, profiles, side_on, fps = _side_frames(inputs.video, setup.profiler, view.led_roi_px,
                                                 progress)
    if clock is None:
        clock = _clock(inputs, rig, top_video, side_on, 1.0 / (fps or view.fps))
    results = load_results(out)
    if results.fits is None or results.points is None:
        raise InputError(f"{out}: the top run has no fits or points to compare with")
    top = top_surface_series(results.fits, results.points, rig.container.radius_mm)
    comparisons = []
    for time_s, profile in zip(times, profiles, strict=True):
        top_time_s = float(clock.top_time_s(time_s))
        top_mm, top_sigma, top_rate = top.wall(top_time_s, profile.azimuth_rad)
        comparisons.append(FrameComparison(profile.azimuth_rad, profile.wall_mm[:, 2],
                                           profile.sigma_z_mm,
                                           profile.pose_sigma_z_mm, top_mm, top_sigma, top_rate,
                                           clock.sigma_s, top.nearest_frame(top_time_s)))
    summary = summarise(comparisons, rig.container.radius_mm)
    run = LateralRun(board, clock, len(times), summary)
    _write_frames(out / "lateral.csv", times, clock, comparisons)
    _write_profiles(out / "lateral_profile.csv", times, clock, profiles, comparisons)
    description = _description(inputs, run)
    (out / "lateral.json").write_text(json.dumps(description, indent=2) + "\n")
    figure = out / "lateral.png"
    _plot(figure, clock.top_time_s(np.array(times)), profiles, comparisons)
    add_report_section(report or out, "Side camera", [*run.lines()], figure, "lateral",
                       description)
    return run


def _frame_row(comparison: FrameComparison) -> list[str]:
    difference = comparison.difference_mm
    used = np.isfinite(difference)
    if not used.any():
        return [str(int(np.isfinite(comparison.side_mm).sum())), "", "", "", "", ""]
    return [str(int(used.sum())), f"{np.mean(comparison.side_mm[used]):.4f}",
            f"{np.mean(comparison.top_mm[used]):.4f}", f"{np.mean(difference[used]):.4f}",
            f"{comparison.rms_difference_mm:.4f}", f"{comparison.rms_predicted_mm:.4f}"]


def _write_frames(path: Path, times: list[float], clock: LateralClock,
                  comparisons: list[FrameComparison]) -> None:
    with path.open("w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["frame", "t_lateral_s", "t_s", "wall_points", "side_mean_mm",
                         "top_mean_mm", "difference_mean_mm", "difference_rms_mm",
                         "predicted_sigma_mm"])
        for index, (time_s, comparison) in enumerate(zip(times, comparisons, strict=True)):
            writer.writerow([index, f"{time_s:.6f}", f"{float(clock.top_time_s(time_s)):.6f}",
                             *_frame_row(comparison)])


def _cell(value: float, digits: int = 4) -> str:
    return f"{value:.{digits}f}" if np.isfinite(value) else ""


def _write_profiles(path: Path, times: list[float], clock: LateralClock,
                    profiles: list[WallProfile], comparisons: list[FrameComparison]) -> None:
    with path.open("w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["frame", "t_s", "column_px", "azimuth_deg", "X_mm", "Y_mm", "Z_mm",
                         "sigma_Z_mm", "pose_sigma_Z_mm", "top_Z_mm", "top_sigma_Z_mm",
                         "top_rate_mm_s"])
        for index, (time_s, profile, comparison) in enumerate(
                zip(times, profiles, comparisons, strict=True)):
            t_s = f"{float(clock.top_time_s(time_s)):.6f}"
            for k in np.flatnonzero(profile.valid & (profile.column_px % PROFILE_STEP_PX == 0)):
                writer.writerow([index, t_s, int(profile.column_px[k]),
                                 _cell(np.degrees(profile.azimuth_rad[k]), 3),
                                 *(_cell(v) for v in profile.wall_mm[k]),
                                 _cell(profile.sigma_z_mm[k]), _cell(profile.pose_sigma_z_mm[k]),
                                 _cell(comparison.top_mm[k]),
                                 _cell(comparison.top_sigma_mm[k]),
                                 _cell(comparison.top_rate_mm_s[k], 2)])


def _description(inputs: LateralInput, run: LateralRun) -> dict[str, Any]:
    """lateral.json: inputs, board pose, clock paths, the comparison's summary (NaN: null)."""
    def finite(value: float) -> float | None:
        return float(value) if np.isfinite(value) else None

    return {
        "video": str(inputs.video), "view_file": str(inputs.view_file),
        "board_images": [str(p) for p in inputs.board_images], "frames": run.frames,
        "camera_position_mm": [float(v) for v in run.board.camera_position_mm],
        "camera_position_sigma_mm": [float(v) for v in run.board.position_sigma_mm],
        "camera_angle_sigma_deg": [float(v) for v in run.board.angle_sigma_deg],
        "board_reprojection_rms_px": run.board.reprojection_rms_px,
        "clock": {"top_minus_side_s": run.clock.offset_s, "sigma_s": run.clock.sigma_s,
                  "paths": [asdict(p) for p in run.clock.paths],
                  "disagreement_sigmas": run.clock.disagreement_sigmas},
        "comparison": {key: finite(value) if isinstance(value, float) else value
                       for key, value in asdict(run.summary).items()},
    }


def _plot(path: Path, top_time_s: np.ndarray, profiles: list[WallProfile],
          comparisons: list[FrameComparison]) -> None:
    """Side and top heights at the wall point nearest the view's centre, and the per-frame
    RMS of side − top against what both σ predict."""
    figure, (heights, differences) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    side, top = [], []
    for profile, comparison in zip(profiles, comparisons, strict=True):
        middle = len(profile.column_px) // 2
        side.append(comparison.side_mm[middle])
        top.append(comparison.top_mm[middle])
    rms = [c.rms_difference_mm for c in comparisons]
    predicted = [c.rms_predicted_mm for c in comparisons]
    heights.plot(top_time_s, side, label="side camera: contact line")
    heights.plot(top_time_s, top, label="top camera: modal fit at the wall")
    heights.set_ylabel("height at the wall [mm]")
    heights.legend()
    differences.plot(top_time_s, rms, label="RMS of side − top")
    differences.plot(top_time_s, predicted, label="predicted by both σ")
    differences.set_ylabel("[mm]")
    differences.set_xlabel("time on the top camera's clock [s]")
    differences.legend()
    figure.tight_layout()
    figure.savefig(path, dpi=80)
    plt.close(figure)
