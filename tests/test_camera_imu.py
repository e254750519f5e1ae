"""The camera's own IMU: GoPro's GPMF track against GoPro's parser's numbers, the simulator's
camera IMU, and the clocks linked by the acceleration both accelerometers feel."""

from __future__ import annotations

import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from sds_arduino.clock import align_by_acceleration
from sds_arduino.protocol import format_record, unwrap_time_s
from sds_camera.camera_imu import (
    HERO5_TO_OPTICAL,
    CameraImu,
    CameraImuError,
    read_camera_imu,
    read_sidecar,
    sidecar_path,
    write_sidecar,
)
from sds_camera.frame_source import VideoFileSource
from sds_record.import_sd import import_sd
from sds_record.recorded_series import read_accelerations
from sds_sim.arduino import CATAPULT_DURATION_S, STANDARD_GRAVITY, arduino_records
from sds_sim.camera_imu import camera_imu
from sds_sim.scenario import Scenario, load_scenario
from sds_sloshing.gravity import free_fall, gravity_regime
from sds_workflows.camera_imu_mcap import write_imu_mcap

SCENARIOS = Path(__file__).resolve().parents[1] / "config" / "scenarios"


def test_the_hero5_axis_map_is_a_rotation_to_the_optical_frame() -> None:
    assert np.allclose(HERO5_TO_OPTICAL @ HERO5_TO_OPTICAL.T, np.eye(3))
    assert np.linalg.det(HERO5_TO_OPTICAL) == pytest.approx(1.0)
    # GoPro's Z (up) is the image's −y, its X (the camera's left) −x, its Y (backwards) −z
    np.testing.assert_allclose(HERO5_TO_OPTICAL, [[0, -1, 0], [-1, 0, 0], [0, 0, -1]])


def test_sidecar_round_trip_and_bad_sidecar(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    imu = CameraImu(np.arange(5) * 0.005, rng.normal(0, 1, (5, 3)), np.arange(9) * 0.0025,
                    rng.normal(0, 1, (9, 3)), "test")
    video = tmp_path / "run.mp4"
    write_sidecar(imu, sidecar_path(video))
    back = read_camera_imu(video)
    assert back is not None
    np.testing.assert_allclose(back.accel_m_s2, imu.accel_m_s2, atol=1e-6)
    np.testing.assert_allclose(back.gyro_time_s, imu.gyro_time_s, atol=1e-6)
    sidecar_path(video).write_text("sensor,t_s,x,y,z\naccel,0.0,1,2,oops\n")
    with pytest.raises(CameraImuError, match=":2:"):
        read_sidecar(sidecar_path(video))
    assert read_camera_imu(tmp_path / "folder_of_images") is None


@pytest.mark.shared_data
def test_karma_gpmf_matches_gopros_parser(shared_data: Path) -> None:
    """SOURCE.txt's numbers, read by GoPro's C parser, in the stored Z, X, Y order."""
    imu = read_camera_imu(shared_data / "gopro_gpmf_samples" / "karma.mp4")
    assert imu is not None
    stored_accel = imu.accel_m_s2 @ HERO5_TO_OPTICAL    # back to Z, X, Y
    stored_gyro = imu.gyro_rad_s @ HERO5_TO_OPTICAL
    assert len(imu.accel_time_s) == 2397 and len(imu.gyro_time_s) == 4795
    np.testing.assert_allclose(stored_accel.mean(axis=0), [9.6882, -0.1612, -0.2092], atol=1e-3)
    np.testing.assert_allclose(stored_accel[0], [10.1579, -0.8517, -3.701], atol=1e-3)
    np.testing.assert_allclose(stored_accel[-1], [9.9617, -4.1172, 2.8014], atol=1e-3)
    np.testing.assert_allclose(stored_gyro.mean(axis=0), [-0.0181, 0.0135, -0.0153], atol=1e-3)
    np.testing.assert_allclose(stored_gyro[0], [0.0458, 0.0186, 0.0333], atol=1e-3)
    np.testing.assert_allclose(stored_gyro[-1], [-0.7944, -0.0096, 0.0059], atol=1e-3)
    accel_period, gyro_period = 1 / 200, 1 / 400
    assert imu.accel_time_s[0] == pytest.approx(-0.1352, abs=accel_period)
    assert imu.accel_time_s[-1] == pytest.approx(12.8063, abs=accel_period)
    assert imu.gyro_time_s[0] == pytest.approx(-0.1363, abs=gyro_period)
    assert imu.gyro_time_s[-1] == pytest.approx(12.8409, abs=gyro_period)
    # upright and level on the drone: the specific force points up, the image's −y
    assert imu.accel_m_s2.mean(axis=0)[1] == pytest.approx(-9.69, abs=0.01)


def _streams(scenario: Scenario) -> tuple[np.ndarray, np.ndarray, CameraImu]:
    """The Arduino's accelerometer (device clock [s], rig frame [m/s²]) and the camera's."""
    records = arduino_records(scenario)
    device_s = unwrap_time_s([r.t_us for r in records])
    imu_rows = [k for k, r in enumerate(records) if r.kind == "IMU"]
    device = np.array([records[k].values for k in imu_rows]) * STANDARD_GRAVITY / 1000
    camera = camera_imu(scenario)
    assert camera is not None
    return device_s[imu_rows], device, camera


def _true_offset_s(scenario: Scenario, device_time_s: float) -> float:
    """Camera-IMU time minus device time at a device time (offset, drift and IMU offset)."""
    a = scenario.arduino
    video_s = device_time_s / (1 + a.clock_drift_ppm * 1e-6) - a.clock_offset_s
    return video_s + scenario.camera_imu.offset_s - device_time_s


@pytest.mark.parametrize("name", ["ground_kick", "drop_4p7s", "drop_9p3s_catapult"])
@pytest.mark.parametrize("seed", [0, 1])
def test_the_accelerometers_link_the_clocks_within_2_ms(name: str, seed: int) -> None:
    scenario = load_scenario(SCENARIOS / f"{name}.yaml", {"seed": seed})
    scenario = replace(scenario, camera_imu=replace(scenario.camera_imu, offset_s=0.0042))
    device_t, device, camera = _streams(scenario)
    # the camera's samples turned into the rig's frame (optical → world: Rᵀ)
    in_rig = camera.accel_m_s2 @ scenario.rig.world_to_camera.rotation
    link = align_by_acceleration(device_t, device, camera.accel_time_s, in_rig)
    assert link is not None
    truth = _true_offset_s(scenario, 0.5 * (link.window_s[0] + link.window_s[1]))
    assert abs(link.offset_s - truth) < 0.002, (link, truth)
    assert link.sigma_s < 0.001
    if name != "ground_kick":
        # a release or a launch changes |a| strongly: magnitudes alone, without the rig's
        # camera pose, give it too (a lateral kick hardly changes |a|: 2.9 ms off)
        magnitude = align_by_acceleration(device_t, np.linalg.norm(device, axis=1),
                                          camera.accel_time_s,
                                          np.linalg.norm(camera.accel_m_s2, axis=1))
        assert magnitude is not None and abs(magnitude.offset_s - truth) < 0.002, magnitude


def test_no_excitation_or_no_overlap_gives_no_link() -> None:
    rng = np.random.default_rng(0)
    t = np.arange(0, 2, 0.005)
    kicked = rng.normal(0, 0.05, (len(t), 3))
    kicked[200:212, 0] += 4.0
    quiet = rng.normal(0, 0.05, (len(t), 3))
    assert align_by_acceleration(t, kicked, t + 0.3, kicked) is not None
    assert align_by_acceleration(t, kicked, t, quiet) is None        # the camera saw nothing
    assert align_by_acceleration(t, kicked, t[:6], kicked[:6]) is None


def test_free_fall_is_found_in_a_drop_and_not_in_a_kick() -> None:
    for name, falls in (("drop_4p7s", True), ("ground_kick", False),
                        ("drop_9p3s_catapult", True)):
        scenario = load_scenario(SCENARIOS / f"{name}.yaml")
        imu = camera_imu(scenario)
        assert imu is not None
        fall = free_fall(imu.accel_time_s, imu.accel_m_s2)
        assert (fall is not None) == falls, name
        if fall is not None:
            events = scenario.events
            # free fall begins at the release, or when the catapult's launch pulse ends (the
            # longest stretch may begin after the lateral kick that follows)
            start = events.release_s if events.catapult_s is None else \
                events.catapult_s + CATAPULT_DURATION_S
            assert start is not None and fall.start_s > start - 0.02, (fall, start)
            assert fall.end_s - fall.start_s > 0.5 * scenario.duration_s
            assert fall.residual_m_s2 < 0.2


@pytest.mark.parametrize("name", ["ground_kick", "drop_4p7s"])
def test_sds_clock_link_on_a_simulated_run(name: str, tmp_path: Path) -> None:
    """Video, camera IMU and Arduino log of the simulator, its clock offset known."""
    sds = str(Path(sys.executable).with_name("sds"))
    scenario = load_scenario(SCENARIOS / f"{name}.yaml")
    subprocess.run([sds, "simulate", str(SCENARIOS / f"{name}.yaml"), "--out",
                    str(tmp_path), "--seconds", "2", "--scale", "0.25"], check=True,
                   capture_output=True)
    x, y = (v * 0.25 for v in scenario.events.led_position_px)
    command = [sds, "clock-link", "--video", str(tmp_path / "video.mp4"), "--arduino",
               str(tmp_path / "arduino" / "SDS_LOG.TXT"), "--rig", str(scenario.rig_file)]
    done = subprocess.run([*command, "--led-roi", str(round(x) - 8), str(round(y) - 8), "16",
                           "16"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    found = re.search(r"acceleration: camera − device = ([-+.\d]+) s", done.stdout)
    led = re.search(r"LED: +camera − device = ([-+.\d]+) s ± ([.\d]+) ms", done.stdout)
    agreement = re.search(r"disagreement: ([-+.\d]+) ms ± ([.\d]+) ms", done.stdout)
    assert found and led and agreement, done.stdout
    device_s = 0.5 * (1.3 + 2.3)           # the excitation lies in the first two seconds
    truth = _true_offset_s(scenario, device_s)
    assert abs(float(found.group(1)) - truth) < 0.002, (done.stdout, truth)
    assert abs(float(agreement.group(1))) < 2 * float(agreement.group(2)), done.stdout
    alone = subprocess.run(command, capture_output=True, text=True)   # no LED: acceleration
    assert alone.returncode == 0 and "LED:          none" in alone.stdout, alone.stdout


def test_a_recorded_free_fall_sets_microgravity(tmp_path: Path) -> None:
    """The Arduino's log (import-sd) and the camera's IMU (import-gopro's writer) in MCAP:
    either one's free fall makes the analysis microgravity; a ground kick does not."""
    for name, falls in (("drop_4p7s", True), ("ground_kick", False)):
        scenario = load_scenario(SCENARIOS / f"{name}.yaml", {"duration_s": 3.0})
        log = tmp_path / f"{name}.txt"
        log.write_text("".join(format_record(r) for r in arduino_records(scenario)))
        arduino_only = tmp_path / f"{name}_arduino.mcap"
        import_sd(log, arduino_only)
        camera = camera_imu(scenario)
        assert camera is not None
        camera_only = tmp_path / f"{name}_camera.mcap"
        write_imu_mcap(camera, camera_only, 10**9)
        for path, topic in ((arduino_only, "/arduino/imu"), (camera_only, "/camera/imu")):
            streams = read_accelerations(path)
            assert list(streams) == [topic]
            gravity, note = gravity_regime(streams)
            assert (gravity == 0.0) == falls and (topic in note) == falls, (name, topic, note)


@pytest.mark.shared_data
def test_karma_frames_still_decode_at_their_presentation_times(shared_data: Path) -> None:
    source = VideoFileSource(shared_data / "gopro_gpmf_samples" / "karma.mp4")
    times = np.array([frame.time_ns for frame in source.frames()]) * 1e-9
    source.close()
    assert len(times) == 362
    np.testing.assert_allclose(np.diff(times), 1001 / 30000, atol=2e-4)
