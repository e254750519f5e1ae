"""The README's "A real rig, step by step" commands, run as written on small simulated inputs:
a camera's checkerboard images, the planned tilt table's images and a drop's video, all
rendered at half the GoPro's size with one true camera the rig file is never told."""

from __future__ import annotations

import shlex
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from sds_model.camera.files import load_camera
from sds_model.rig import load_rig, save_rig
from sds_recon.calibration.board import Checkerboard
from sds_recon.results import load_results
from sds_sim.scenario import load_scenario
from sds_sim.simulate import simulate
from sds_sim.tilt_series import render_surfaces
from sds_sim.true_rig import camera_as_calibrated
from sds_workflows.demo import DEMO_SCENARIO
from sds_workflows.rig_calibration import FRAMES_PER_STILL, known_surfaces
from test_calibration import board_poses, render_board

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[1]
SDS = str(Path(sys.executable).with_name("sds"))
SCALE = 0.5
"""The inputs' size against the GoPro's 4K: the tracker's windows still hold a spot."""


def readme_steps() -> list[list[str]]:
    """The `sds` commands of the README's step-by-step block, in order, comments dropped."""
    text = (REPO / "README.md").read_text()
    block = text.split("## A real rig, step by step", 1)[1].split("```")[1]
    return [shlex.split(line.split("#")[0]) for line in block.splitlines()
            if line.startswith("sds ")]


def expanded(command: list[str], folder: Path, substitutes: dict[str, list[str]]
             ) -> list[str]:
    """A README command with its globs expanded in `folder` (as a shell would) and the
    arguments only a real rig has (a live camera) replaced by `substitutes`."""
    words: list[str] = [SDS]
    for word in command[1:]:
        if word in substitutes:
            words += substitutes[word]
        elif "*" in word:
            words += sorted(str(p.relative_to(folder)) for p in folder.glob(word))
        else:
            words.append(word)
    return words


def test_the_readmes_real_rig_steps_run_as_written(tmp_path: Path) -> None:
    """Every step of the README's real-rig block, in order, each exit code 0: the camera
    calibrated from rendered checkerboards, the rig planned and calibrated from the table's
    rendered images (a burst per surface), 2 s of a drop's video run through the graph (a
    file for the live camera, no Arduino), then processed again from its recording, analysed
    and viewed."""
    steps = readme_steps()
    assert [s[1] for s in steps] == ["calibrate", "calibrate", "calibrate", "run", "process",
                                     "analyze", "view"], steps
    stelium = load_rig(REPO / "config" / "rigs" / "stelium.yaml")
    true_camera = camera_as_calibrated(stelium.camera, stelium.camera_sigma, 1.0,
                                       np.random.default_rng(5))
    seen = true_camera.scaled(SCALE)
    # 1. Checkerboards as the README's command states them (9x6, 25 mm).
    board_folder = tmp_path / "board"
    board_folder.mkdir()
    board = Checkerboard(9, 6, 25.0)
    for index, pose in enumerate(board_poses(seen, board, 10, seed=5)):
        cv2.imwrite(str(board_folder / f"b{index:02d}.jpg"), render_board(seen, pose, board),
                    [cv2.IMWRITE_JPEG_QUALITY, 95])
    substitutes = {"/dev/video0": [], "--camera": []}
    run = expanded(steps[0], tmp_path, substitutes)
    done = subprocess.run(run, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, (run, done.stdout, done.stderr)
    # 2. The rig as designed with that camera file.
    designed = replace(stelium, camera=load_camera(tmp_path / "camera.yaml"),
                       camera_file=tmp_path / "camera.yaml")
    save_rig(designed, tmp_path / "designed.yaml")
    run = expanded(steps[1], tmp_path, substitutes)
    done = subprocess.run(run, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, (run, done.stdout, done.stderr)
    # 3. A burst of images at each planned surface, rendered with the true camera.
    true = replace(stelium, camera=true_camera)
    surfaces = known_surfaces(tmp_path / "surfaces.csv")
    series = render_surfaces(true, surfaces, SCALE, seed=5, frames=FRAMES_PER_STILL)
    (tmp_path / "table").mkdir()
    for index, image in enumerate(series.images):
        for shot, frame in enumerate([image, *series.repeats[index]]):
            cv2.imwrite(str(tmp_path / "table" / f"s{index:02d}_{shot}.png"), frame)
    run = expanded(steps[2], tmp_path, substitutes)
    done = subprocess.run(run, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, (run, done.stdout, done.stderr)
    # Image bursts are not the drop's video (its codec): they give no video σ scale.
    record = load_rig(tmp_path / "rig.yaml").calibration or {}
    assert "spot_excess_sigma_px" in record and "spot_sigma_scale" not in record
    # 4. The drop: a video for the live camera, no Arduino.
    scenario = replace(load_scenario(DEMO_SCENARIO, {"scale": SCALE, "duration_s": 2.0}),
                       rig=true)
    video = simulate(scenario, tmp_path / "simulation").video
    substitutes = {"/dev/video0": ["--no-arduino"], "--camera": ["--video", str(video)]}
    for step in steps[3:]:
        run = expanded(step, tmp_path, substitutes)
        done = subprocess.run(run, cwd=tmp_path, capture_output=True, text=True, timeout=900)
        assert done.returncode == 0, (run, done.stdout, done.stderr)
    for path in ("drop1/recording.mcap", "drop1/results/points.csv",
                 "drop1_again/points.csv", "drop1_analysis/report.html", "drop1_view.rrd"):
        assert (tmp_path / path).exists(), path
    again = load_results(tmp_path / "drop1_again").points
    assert again is not None and len(again) > 50 * 17   # the drop's spots, measured again
