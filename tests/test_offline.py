"""`sds process` / `sds export` on bad input, and the result files' round trip."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from builtin_interfaces.msg import Time
from rclpy.serialization import serialize_message
from sds_arduino.protocol import unwrap_time_s
from sds_camera.camera_imu import read_camera_imu
from sds_model.rig import LaserDiode, Rig, load_rig, save_rig
from sds_recon.reconstruction import SurfacePoints
from sds_recon.results import COLUMNS, ResultsWriter, load_results
from sds_record.mcap_files import McapRecorder
from sds_ros.arduino_msg import SensorSpec, record_message
from sds_ros.image_msg import image_to_msg
from sds_ros.point_cloud import points_to_cloud
from sds_sim.arduino import arduino_records
from sds_sim.optics import ray_surface_points
from sds_sim.scenario import load_scenario
from sds_sim.simulate import simulate
from sds_workflows.pipeline import FRAMES_BEFORE_MODEL, RecordingError, mcap_frames
from sensor_msgs.msg import RegionOfInterest
from std_msgs.msg import Header

from sds_msgs.msg import CameraModel, LaserSpot, LaserSpotArray

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


def test_a_frame_without_line_samples_adds_no_row(tmp_path: Path) -> None:
    """A rig without a line laser: each frame's line is empty (`sds process` failed on it)."""
    writer = ResultsWriter(tmp_path)
    empty = np.zeros(0)
    writer.add_columns("line", [0, 0.0, empty, empty, empty, empty, empty.astype(np.uint8)])
    writer.add_columns("line", [1, 0.033, [5.0, 6.0], [7.0, 8.0], 0.1, 200.0, [0, 1]])
    with pytest.raises(ValueError, match="different lengths"):
        writer.add_columns("line", [2, 0.067, [5.0, 6.0], [7.0, 8.0, 9.0], 0.1, 200.0, 0])
    writer.close()
    line = load_results(tmp_path).line
    assert list(line["frame"]) == [1, 1] and list(line["flags"]) == [0, 1]


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
                   "missing.mcap: no such file")


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
    # from the first frame on, as the graph publishes it (sds export gives the same span)
    assert results.camera_imu["t_s"].min() >= 0
    assert len(results.camera_imu) == np.sum(imu.accel_time_s >= 0) + np.sum(imu.gyro_time_s >= 0)
    accel = results.camera_imu[np.isfinite(results.camera_imu["ax_m_s2"])]
    np.testing.assert_allclose(accel["az_m_s2"], imu.accel_m_s2[imu.accel_time_s >= 0, 2],
                               atol=1e-6)


def test_export_finds_the_free_fall_keeps_the_tof_and_times_early_readings_negative(
        repo: Path, tmp_path: Path) -> None:
    """A recording of a drop with the Arduino's streams starting 0.5 s before the first frame:
    `sds export` analyses it as microgravity (the IMU's free fall), with the ToF's estimate,
    and the IMU and ToF rows recorded before the first frame have negative times."""
    scenario = load_scenario(repo / "config" / "scenarios" / "drop_4p7s.yaml", {"duration_s": 3.0})
    rig = scenario.rig
    emitters = np.array([d.emitter_mm for d in rig.diodes])
    directions = np.array([d.direction for d in rig.diodes])
    ids = np.array([d.laser_id for d in rig.diodes])
    first_frame_ns = 10**9 + 5 * 10**8          # the Arduino's device clock starts at 1 s
    path = tmp_path / "drop.mcap"
    recorder = McapRecorder(path)
    for topic, type_name in (("/tracker/spots", "sds_msgs/msg/LaserSpotArray"),
                             ("/recon/points", "sensor_msgs/msg/PointCloud2"),
                             ("/arduino/imu", "sensor_msgs/msg/Imu"),
                             ("/arduino/tof", "sensor_msgs/msg/Range")):
        recorder.add_topic(topic, type_name)
    messages: list[tuple[int, str, object]] = []
    for frame in range(scenario.frame_count):
        time_s = frame / scenario.fps
        stamp_ns = first_frame_ns + round(time_s * 1e9)
        header = Header(stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9))
        hits = ray_surface_points(scenario.surface_at(time_s), emitters, directions, time_s)
        spots = [LaserSpot(laser_id=int(i), x_px=1.0, y_px=1.0, sigma_px=0.1) for i in ids]
        messages.append((stamp_ns, "/tracker/spots",
                         LaserSpotArray(header=header, frame_index=frame, spots=spots)))
        messages.append((stamp_ns, "/recon/points", points_to_cloud(header, SurfacePoints(
            ids, hits, np.full(len(ids), 0.01), np.zeros(len(ids))))))
    records = arduino_records(scenario)
    device_s = unwrap_time_s([r.t_us for r in records])
    for record, t_s in zip(records, device_s - device_s[0], strict=True):
        if record.kind in ("IMU", "TOF"):
            stamp_ns = 10**9 + round(t_s * 1e9)
            stamp = Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
            messages.append((stamp_ns, f"/arduino/{record.kind.lower()}",
                             record_message(record, stamp, round(t_s * 1e6), SensorSpec())))
    for stamp_ns, topic, msg in sorted(messages, key=lambda item: item[0]):
        recorder.write(topic, serialize_message(msg), stamp_ns, stamp_ns)
    recorder.close()
    done = sds("export", str(path), "--rig", str(scenario.rig_file), "--out",
               str(tmp_path / "out"))
    assert done.returncode == 0, done.stderr
    assert "free fall" in done.stdout and "microgravity" in done.stdout, done.stdout
    results = load_results(tmp_path / "out")
    assert results.imu is not None and results.tof is not None
    for table in (results.imu, results.tof):
        early = table["t_s"] < 0
        assert early.any() and table["t_s"][early].min() >= -0.5 - 1e-6
        assert np.all(np.diff(table["t_s"]) > 0)      # in time order, none squeezed onto 0
    analysis = yaml.safe_load((tmp_path / "out" / "analysis.json").read_text())
    assert analysis["tof"] and analysis["tof"][0]["estimates"], analysis["tof"]


def _frames_recording(path: Path, frames: int, model_after: int | None) -> None:
    """`frames` small mono8 frames 1/30 s apart, the camera model (region at x 40, y 24)
    logged after frame `model_after` (None: never), as a late-matching recorder logs it."""
    recorder = McapRecorder(path)
    recorder.add_topic("/camera/image", "sensor_msgs/msg/Image")
    recorder.add_topic("/camera/camera_model", "sds_msgs/msg/CameraModel", latched=True)
    model = CameraModel(roi=RegionOfInterest(x_offset=40, y_offset=24, width=8, height=6))
    for index in range(frames):
        stamp_ns = 10**9 + index * 10**9 // 30
        image = np.full((6, 8), index, np.uint8)
        time = Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
        recorder.write("/camera/image", serialize_message(image_to_msg(image, time, "camera")),
                       stamp_ns, stamp_ns)
        if index == model_after:
            recorder.write("/camera/camera_model", serialize_message(model), stamp_ns + 1,
                           stamp_ns + 1)
    recorder.close()


def test_frames_recorded_before_the_camera_model_wait_for_it(tmp_path: Path) -> None:
    _frames_recording(tmp_path / "late.mcap", 12, model_after=3)
    frames = list(mcap_frames(tmp_path / "late.mcap"))
    assert [f.index for f in frames] == list(range(12))
    assert [int(f.red[0, 0]) for f in frames] == list(range(12))   # in recorded order
    assert all(f.offset == (40, 24) for f in frames)
    np.testing.assert_allclose([f.time_s for f in frames], np.arange(12) / 30, atol=1e-9)
    _frames_recording(tmp_path / "none.mcap", 5, model_after=None)
    with pytest.raises(RecordingError, match="camera frames but no camera model"):
        list(mcap_frames(tmp_path / "none.mcap"))
    _frames_recording(tmp_path / "far.mcap", FRAMES_BEFORE_MODEL + 2, model_after=None)
    with pytest.raises(RecordingError, match=f"{FRAMES_BEFORE_MODEL + 1} camera frames before "
                                             "any camera model"):
        list(mcap_frames(tmp_path / "far.mcap"))
