"""`sds process` / `sds export` on bad input, and the result files' round trip."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from rclpy.serialization import serialize_message
from sds_camera.camera_imu import read_camera_imu
from sds_model.rig import LaserDiode, Rig, load_rig, save_rig
from sds_recon.results import COLUMNS, ResultsWriter, load_results
from sds_record.mcap_files import McapRecorder
from sds_sim.scenario import load_scenario
from sds_sim.simulate import simulate
from std_msgs.msg import Header

SDS = str(Path(sys.executable).with_name("sds"))


def sds(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([SDS, *args], capture_output=True, text=True, timeout=120)


def test_results_round_trip_with_missing_values(tmp_path: Path) -> None:
    writer = ResultsWriter(tmp_path)
    writer.add("spots", [(0, 0.0, 3, 10.5, 20.25, 10.5, 20.25, 0.04, 250.0, 1, 0),
                         (0, 0.0, 4, float("nan"), float("nan"), float("nan"), float("nan"),
                          0.0, 0.0, 0, 1)])
    writer.add_fit((0, 0.0, 0.1, 0.0, 0.0, 0.0, 0.0, 0.99, 0.02, 0.008, 20, 1),
                   ("mean", "lateral_1_cos"), [0.1, 2.5])
    writer.add_fit((1, 0.0333, *(float("nan"),) * 8, 2, 0), (), [])
    writer.close()
    results = load_results(tmp_path)
    assert results.spots["x_px"][0] == 10.5 and np.isnan(results.spots["x_px"][1])
    assert list(results.spots["laser_id"]) == [3, 4] and results.spots["laser_id"].dtype == int
    assert results.fits["lateral_1_cos_mm"][0] == 2.5 and np.isnan(results.fits["p00_mm"][1])
    assert results.points is None and set(results.columns) == {"spots", "fits"}
    assert list(results.columns["spots"]) == list(COLUMNS["spots"])


def one_line_error(done: subprocess.CompletedProcess, text: str) -> None:
    assert done.returncode == 2, done.stdout + done.stderr
    assert text in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr


def test_bad_input_gives_one_line_and_exit_2(repo: Path, tmp_path: Path) -> None:
    rig = repo / "config" / "rigs" / "stelium.yaml"
    broken = yaml.safe_load(rig.read_text())
    del broken["container"]
    broken["camera"]["model"] = str(repo / "config" / "cameras" / "gopro_hero5_session.yaml")
    broken_rig = tmp_path / "broken.yaml"
    broken_rig.write_text(yaml.safe_dump(broken))
    video = tmp_path / "garbage.mp4"
    video.write_bytes(b"not a video" * 100)
    one_line_error(sds("process", "--video", str(video), "--rig", str(broken_rig), "--out",
                       str(tmp_path / "a")), "container")
    one_line_error(sds("process", "--video", str(video), "--rig", str(rig), "--out",
                       str(tmp_path / "b")), "garbage.mp4")
    recording = McapRecorder(tmp_path / "no_frames.mcap")
    recording.add_topic("/test/header", "std_msgs/msg/Header")
    recording.write("/test/header", serialize_message(Header(frame_id="x")), 1, 1)
    recording.close()
    one_line_error(sds("process", "--mcap", str(tmp_path / "no_frames.mcap"), "--rig", str(rig),
                       "--out", str(tmp_path / "c")), "no camera frames")
    one_line_error(sds("export", str(tmp_path / "no_frames.mcap"), "--out",
                       str(tmp_path / "d")), "carries no rig")
    one_line_error(sds("export", str(tmp_path / "no_frames.mcap"), "--rig", str(rig), "--out",
                       str(tmp_path / "d")), "no laser spots")
    one_line_error(sds("export", str(tmp_path / "missing.mcap"), "--out", str(tmp_path / "e")),
                   "no such recording")


@pytest.mark.parametrize("table", sorted(COLUMNS))
def test_every_column_is_described_with_its_unit_or_meaning(table: str) -> None:
    for column, description in COLUMNS[table].items():
        assert description, column
        if column.endswith(("_mm", "_px", "_s", "_deg", "_m_s2")):
            assert "[" in description, column


def leaning_rig(rig_file: Path, target: Path, max_lean_deg: float, seed: int) -> Rig:
    """The rig file with every beam leaning by up to `max_lean_deg` (manufacturing errors)."""
    rig = load_rig(rig_file)
    rng = np.random.default_rng(seed)
    diodes = []
    for diode in rig.diodes:
        lean, azimuth = np.radians(rng.uniform(0.1, max_lean_deg)), rng.uniform(0, 2 * np.pi)
        direction = np.array([np.sin(lean) * np.cos(azimuth), np.sin(lean) * np.sin(azimuth),
                              -np.cos(lean)])
        diodes.append(LaserDiode(diode.laser_id, diode.ring, diode.emitter_mm, direction))
    leaning = replace(rig, diodes=tuple(diodes))
    save_rig(leaning, target)
    return load_rig(target)


def test_process_calibrates_the_beams_from_images_first(repo: Path, tmp_path: Path) -> None:
    """Tilt-table images of a rig whose beams lean: `--calibrate-lasers` finds the leans."""
    nominal = repo / "config" / "rigs" / "stelium.yaml"
    truth = leaning_rig(nominal, tmp_path / "truth_rig.yaml", 0.3, seed=5)
    scenario = load_scenario(repo / "config" / "scenarios" / "tilt_table.yaml",
                             {"rig": str(tmp_path / "truth_rig.yaml"), "fps": 1.0})
    output = simulate(scenario, tmp_path / "sim", codec="png", progress=False)
    images = sorted(str(p) for p in (tmp_path / "sim" / "frames").glob("*.png"))
    assert len(images) == 8
    done = sds("process", "--video", str(tmp_path / "sim" / "frames"), "--fps", "1",
               "--rig", str(nominal),
               "--calibrate-lasers", *images, "--surfaces", str(output.frames),
               "--out", str(tmp_path / "out"), "--no-progress")
    assert done.returncode == 0, done.stderr
    calibrated = load_rig(tmp_path / "out" / "rig_calibrated.yaml")
    errors = [np.degrees(np.arccos(np.clip(c.direction @ t.direction, -1, 1)))
              for c, t in zip(calibrated.diodes, truth.diodes, strict=True)]
    before = [np.degrees(np.arccos(np.clip(-t.direction[2], -1, 1))) for t in truth.diodes]
    # the self-calibration from 8 tilts about one axis (bench/self_calibration.py)
    # (their common part is the camera's turn about the tilt axis, sigma 0.1 deg from one axis)
    assert max(errors) < 0.1 and np.mean(errors) < 0.3 * np.mean(before), (errors, before)
    assert np.linalg.norm(calibrated.camera_position_mm - truth.camera_position_mm) < 0.1
    assert "calibrated rig written" in done.stdout
    assert (tmp_path / "out" / "rig_calibrated.report.html").is_file()
    results = load_results(tmp_path / "out")
    assert sorted(set(results.spots["frame"])) == list(range(8))
    # the camera's own IMU (the simulator's sidecar beside the frames) is a result table
    imu = read_camera_imu(tmp_path / "sim" / "frames")
    assert imu is not None and results.camera_imu is not None
    assert len(results.camera_imu) == len(imu.accel_time_s) + len(imu.gyro_time_s)
    accel = results.camera_imu[np.isfinite(results.camera_imu["ax_m_s2"])]
    np.testing.assert_allclose(accel["az_m_s2"], imu.accel_m_s2[:, 2], atol=1e-6)
