"""Real node processes over Fast DDS: a video enters the graph frame by frame, and the graph stops
cleanly. The frame source runs under `sds graph` exactly as a user starts it."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import NTSC, ntsc_time_ns, random_frames, write_lossless_clip
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from ros_helpers import LATCHED, Probe, SdsGraphRun, pid_alive, wait_until
from sds_camera.camera_imu import CameraImu, sidecar_path, write_sidecar
from sds_model.camera import PinholeCamera, camera_from_dict, save_camera
from sds_recon.results import load_results
from sds_ros.image_msg import msg_to_image
from sds_workflows.demo import height_errors, hidden_points
from sensor_msgs.msg import Image, Imu
from std_msgs.msg import Header

from sds_msgs.msg import CameraModel

pytestmark = pytest.mark.ros

ROI = (40, 30, 200, 150)  # x, y, width, height
IMU_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
FRAMES = random_frames(30, 240, 320, seed=11)


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    return write_lossless_clip(tmp_path_factory.mktemp("graph") / "ntsc.mp4", FRAMES, NTSC)


@pytest.fixture
def probe():
    probe = Probe("test_probe")
    yield probe
    probe.close()


def _roi_red(index: int) -> np.ndarray:
    x, y, w, h = ROI
    return FRAMES[index, y : y + h, x : x + w, 2]


def _stamp_ns(msg) -> int:
    return Time.from_msg(msg.header.stamp).nanoseconds


def test_every_frame_arrives_in_order_with_its_times_and_pixels(clip, probe, tmp_path):
    camera = PinholeCamera(320, 240, 300.0, 301.0, 159.5, 119.5, k1=-0.1)
    camera_file = save_camera(camera, tmp_path / "camera.yaml")
    images = probe.collect(Image, "/camera/image")
    models = probe.collect(CameraModel, "/camera/camera_model", LATCHED)
    # Real time: these random pixels, coded losslessly, take 8-17 ms a frame to decode on a
    # 2-core machine (measured), so four times real time (8 ms a frame) sheds frames there;
    # at 33 ms a frame decoding keeps up with room to spare.
    graph = SdsGraphRun(
        "camera.yaml", "--set", f"camera.source={clip}", "--set", f"camera.roi={list(ROI)}",
        "--set", "camera.channel=red", "--set", "camera.stamp=media", "--set", "camera.rate=1.0",
        "--set", f"camera.camera_model={camera_file}",
    )
    assert graph.wait(timeout=60) == 0, graph.output()
    assert len(images) == len(FRAMES), graph.output()
    for index, msg in enumerate(images):
        assert msg.encoding == "mono8" and msg.header.frame_id == "camera_optical"
        assert abs(_stamp_ns(msg) - ntsc_time_ns(index)) <= 1
        np.testing.assert_array_equal(msg_to_image(msg), _roi_red(index))
    (model,) = models
    assert (model.roi.x_offset, model.roi.y_offset, model.roi.width, model.roi.height) == ROI
    assert (model.full_width, model.full_height, model.channel) == (320, 240, "red")
    assert model.model_type == "pinhole" and model.model_path == str(camera_file.resolve())
    assert camera_from_dict(yaml.safe_load(model.model_yaml)) == camera
    assert "published 30 frames" in graph.output()


def slow_consumer(probe, delay_s: float) -> tuple[list[Image], list[int], list[int]]:
    """A consumer of /camera/image that acknowledges each frame on /camera/frame_ack
    `delay_s` after it came: the frames it got, their publish times and its acks' [ns]."""
    ack_pub = probe.node.create_publisher(Header, "/camera/frame_ack", 10)
    images: list[Image] = []
    published_ns: list[int] = []
    acked_ns: list[int] = []

    def ack_slowly(msg: Image, info) -> None:
        images.append(msg)
        published_ns.append(info["source_timestamp"])
        time.sleep(delay_s)
        acked_ns.append(time.time_ns())
        ack_pub.publish(Header(stamp=msg.header.stamp, frame_id="test"))

    probe.node.create_subscription(Image, "/camera/image", ack_slowly, 10)
    return images, published_ns, acked_ns


def test_flood_pacing_waits_for_acks_and_loses_nothing(clip, probe):
    images, published_ns, acked_ns = slow_consumer(probe, 0.02)   # slower than the decoder
    graph = SdsGraphRun("camera.yaml", "--set", f"camera.source={clip}",
                         "--set", "camera.pacing=flood", "--set", "camera.max_in_flight=1")
    assert graph.wait(timeout=60) == 0, graph.output()
    assert len(images) == len(FRAMES)
    # With one frame in flight, each frame leaves the source only after the previous ack.
    assert all(published_ns[i + 1] > acked_ns[i] for i in range(len(FRAMES) - 1))
    first = _stamp_ns(images[0])
    for index, msg in enumerate(images):
        assert _stamp_ns(msg) - first == ntsc_time_ns(index)
        np.testing.assert_array_equal(msg_to_image(msg), FRAMES[index])


def test_realtime_acks_make_a_file_wait_for_a_consumer_slower_than_real_time(clip, probe):
    """`realtime_acks` (the side camera's file, read as frames, whose every frame the recorder
    keeps): a consumer at half real time gets every frame, each published after the previous
    ack, and the file says how far it fell behind."""
    images, published_ns, acked_ns = slow_consumer(probe, 0.066)   # two frame periods
    graph = SdsGraphRun("camera.yaml", "--set", f"camera.source={clip}",
                         "--set", "camera.realtime_acks=true", "--set", "camera.max_in_flight=1",
                         "--set", "camera.video=false")
    assert graph.wait(timeout=60) == 0, graph.output()
    assert len(images) == len(FRAMES), graph.output()
    assert all(published_ns[i + 1] > acked_ns[i] for i in range(len(FRAMES) - 1))
    assert "behind real time" in graph.output()
    for index, msg in enumerate(images):
        np.testing.assert_array_equal(msg_to_image(msg), FRAMES[index])


def test_composed_graph_runs_camera_and_monitor_in_one_process(clip, tmp_path):
    summary = tmp_path / "summary.json"
    graph = SdsGraphRun("camera_monitor.yaml", "--compose", "--set", f"camera.source={clip}",
                         "--set", "camera.pacing=flood", "--set", f"monitor.summary_path={summary}")
    assert graph.wait(timeout=60) == 0, graph.output()
    assert len(graph.child_pids()) == 1
    result = json.loads(summary.read_text())
    assert result["frames"] == len(FRAMES) and result["out_of_order"] == 0
    assert result["shape"] == [240, 320, 3]


def test_repeat_plays_the_clip_again_as_one_continuous_stream(clip, tmp_path):
    summary = tmp_path / "summary.json"
    graph = SdsGraphRun("camera_monitor.yaml", "--compose", "--set", f"camera.source={clip}",
                         "--set", "camera.pacing=flood", "--set", "camera.repeat=3",
                         "--set", f"monitor.summary_path={summary}")
    assert graph.wait(timeout=60) == 0, graph.output()
    result = json.loads(summary.read_text())
    assert result["frames"] == 3 * len(FRAMES) and result["out_of_order"] == 0


def test_truncated_video_ends_the_stream_with_an_error_and_valid_frames(clip, probe, tmp_path):
    whole = write_lossless_clip(tmp_path / "whole.mkv", FRAMES, NTSC)
    cut = tmp_path / "cut.mkv"
    shutil.copy(whole, cut)
    os.truncate(cut, int(cut.stat().st_size * 0.5))
    images = probe.collect(Image, "/camera/image")
    graph = SdsGraphRun("camera.yaml", "--set", f"camera.source={cut}", "--set", "camera.rate=4.0",
                         "--set", "camera.stamp=media")
    assert graph.wait(timeout=60) == 2, graph.output()
    assert "truncated or corrupt" in graph.output()
    indices = [round(_stamp_ns(msg) * NTSC / 10**9) for msg in images]
    assert 0 < len(indices) < len(FRAMES)
    assert indices == list(range(len(indices))), graph.output()
    for index, msg in zip(indices, images, strict=True):
        np.testing.assert_array_equal(msg_to_image(msg), FRAMES[index])


def test_missing_video_is_a_clear_error_not_a_crash():
    graph = SdsGraphRun("camera.yaml", "--set", "camera.source=/nonexistent/drop.mp4")
    assert graph.wait(timeout=60) == 2
    assert "video file /nonexistent/drop.mp4 does not exist" in graph.output()
    assert "Traceback" not in graph.output()


def test_camera_model_for_another_frame_size_is_refused(clip, repo):
    gopro = repo / "config" / "cameras" / "gopro_hero5_session.yaml"
    graph = SdsGraphRun("camera.yaml", "--set", f"camera.source={clip}",
                        "--set", f"camera.camera_model={gopro}")
    assert graph.wait(timeout=60) == 2
    assert "is for 3840x2160 px frames, the source gives 320x240" in graph.output()
    assert "Traceback" not in graph.output()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGKILL])
def test_signal_to_the_launcher_leaves_no_node_process(clip, sig):
    graph = SdsGraphRun("camera_monitor.yaml", "--set", f"camera.source={clip}",
                         "--set", "camera.wait_for_subscribers=5")
    graph.wait_for_line("waiting for 5 subscriber(s)", timeout=30)
    pids = graph.child_pids()
    assert len(pids) == 2 and all(pid_alive(pid) for pid in pids)
    graph.popen.send_signal(sig)
    code = graph.wait(timeout=30)
    deadline = time.monotonic() + 10
    while any(pid_alive(pid) for pid in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(pid_alive(pid) for pid in pids), graph.output()
    if sig != signal.SIGKILL:
        assert code == 128 + sig, graph.output()     # the shell's convention: stopped, not done
        assert graph.output().count("exited with code 0") == 2, graph.output()


def test_stopping_while_waiting_for_acknowledgements_is_clean(clip):
    graph = SdsGraphRun("camera_monitor.yaml", "--set", f"camera.source={clip}",
                         "--set", "camera.pacing=flood", "--set", "monitor.ack=false",
                         "--set", "monitor.report_period_s=0.2")
    graph.wait_for_line("[monitor] [INFO]", timeout=30)  # frames flow; the source is now blocked
    graph.popen.send_signal(signal.SIGINT)
    assert graph.wait(timeout=30) == 130, graph.output()
    assert graph.output().count("exited with code 0") == 2, graph.output()
    assert "Traceback" not in graph.output()


def test_the_demo_calibrates_a_rig_as_built_and_measures_its_drop_with_the_whole_graph(
        tmp_path, repo):
    """`sds demo` (2 s of the drop): the rig as built is calibrated by the protocol on table
    images with a real camera's imaging, and the summary states the fit's χ² and its own σ
    for unseen surfaces. The drop is measured with the calibrated rig file: every frame
    through camera, tracker, reconstruction, recorder and viewer, the Arduino stream through
    a pseudo-terminal, the analysis, the spots' own check of their σ. No point is wrong:
    the demo's seed once had diodes take the container's rim for a spot that dropped out
    (points 1.7–19.6 mm off, valid); the right ones were within 0.30 mm (the 4.7 s run, 2692
    points), so 1 mm tells them apart.
    (`--exact-rig`, the scenario's own rig file, is run by the Ctrl-C test of
    test_nothing_lost.)"""
    result = subprocess.run([str(Path(sys.executable).with_name("sds")), "demo", "--seconds", "2",
                             "--out", str(tmp_path)], capture_output=True, text=True,
                            timeout=900, check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    assert re.search(r"chi2/dof +[0-9.]+ \(expected", result.stdout), result.stdout
    assert re.search(r"the rig report states tilt ± [0-9.]+ deg", result.stdout), result.stdout
    assert "20 of 20 calibrated" in result.stdout, result.stdout
    assert "frames processed   60 of 60" in result.stdout
    assert not (tmp_path / "ttyARDUINO").is_symlink()     # the stand-in cable is unplugged
    assert "bad lines 0" in result.stdout and "reconnects 0" in result.stdout, result.stdout
    assert "from the sync LED" in result.stdout
    assert re.search(r"σ check +scatter across their beams' paths over their σ: RMS [0-9.]+, "
                     r"the σ are", result.stdout), result.stdout
    for path in ("recording.mcap", "recording.rrd", "analysis/report.html", "results/points.csv",
                 "results/imu.csv", "results/tof.csv"):
        assert (tmp_path / path).is_file(), (path, result.stdout, result.stderr)
    results = load_results(tmp_path / "results")
    for table in (results.imu, results.tof):   # one clock from the first record: none back
        assert table is not None and np.all(np.diff(table["t_s"]) > 0)
    # Wall-clock stamps, yet every frame's time to the nanosecond (not float seconds since 1970)
    assert results.spots is not None
    np.testing.assert_allclose(results.spots["t_s"], results.spots["frame"] / 30, rtol=0,
                               atol=2e-9)
    analysis = json.loads((tmp_path / "analysis" / "analysis.json").read_text())
    lateral_1 = next(m for m in analysis["modes"] if m["mode"] == "lateral_1")
    assert abs(lateral_1["estimates"][0]["frequency_error_pct"]) < 0.5, result.stdout
    heights = re.search(r"heights +RMSE ([0-9.]+) mm against the truth \((\d+) points;",
                        result.stdout)
    assert heights and float(heights.group(1)) < 0.2, result.stdout
    spots = re.search(r"spots +(\d+) \(20 per frame\): (\d+) lost", result.stdout)
    assert spots and int(heights.group(2)) == int(spots.group(1)) - int(spots.group(2))
    assert results.points is not None
    points = results.points[results.points["laser_id"] != 65535]
    errors, _ = height_errors(tmp_path / "simulation" / "truth" / "spots.csv", points)
    assert len(errors) > 50 * 17 and np.abs(errors).max() < 1.0, np.abs(errors).max()
    assert hidden_points(tmp_path / "simulation" / "truth" / "spots.csv", points) == 0


def test_the_camera_imu_beside_a_video_is_published_on_the_frames_clock(clip, probe, tmp_path):
    """A sidecar IMU file (the simulator's format): every sample from the first frame on is
    published once, in order, stamped on the frames' clock, in the optical frame."""
    video = tmp_path / "clip.mp4"
    shutil.copy(clip, video)
    rng = np.random.default_rng(3)
    accel_t, gyro_t = np.arange(-0.1, 1.2, 0.005), np.arange(-0.1, 1.2, 0.0025)
    imu = CameraImu(accel_t, rng.normal(0, 1, (len(accel_t), 3)), gyro_t,
                    rng.normal(0, 0.1, (len(gyro_t), 3)), "test")
    write_sidecar(imu, sidecar_path(video))
    messages = probe.collect(Imu, "/camera/imu", IMU_QOS)
    images = probe.collect(Image, "/camera/image")
    # Frames decoded ahead (no packets): four times real time sheds no frame on any machine.
    graph = SdsGraphRun("camera.yaml", "--set", f"camera.source={video}", "--set",
                        "camera.stamp=media", "--set", "camera.rate=4.0",
                        "--set", "camera.video=false")
    assert graph.wait(timeout=60) == 0, graph.output()
    last_frame_s = ntsc_time_ns(len(FRAMES) - 1) * 1e-9
    accel_t, gyro_t = (t[(t >= 0) & (t <= last_frame_s)] for t in (accel_t, gyro_t))
    assert wait_until(lambda: len(messages) == len(accel_t) + len(gyro_t),
                      timeout=10), (len(messages), graph.output())
    stamps = np.array([_stamp_ns(m) for m in messages]) * 1e-9
    assert np.all(np.diff(stamps) >= 0) and stamps[0] >= 0
    accel = [m for m in messages if m.angular_velocity_covariance[0] == -1]
    gyro = [m for m in messages if m.linear_acceleration_covariance[0] == -1]
    assert len(accel) == len(accel_t) and len(gyro) == len(gyro_t)
    first = np.flatnonzero(imu.accel_time_s >= 0)[0]
    a = accel[0].linear_acceleration
    np.testing.assert_allclose([a.x, a.y, a.z], imu.accel_m_s2[first], atol=1e-6)
    assert _stamp_ns(accel[0]) * 1e-9 == pytest.approx(imu.accel_time_s[first], abs=1e-6)
    assert accel[0].header.frame_id == "camera_optical"
    assert len(images) == len(FRAMES) and "camera IMU from" in graph.output()


def test_a_video_without_telemetry_says_so_in_one_line(clip, probe):
    messages = probe.collect(Imu, "/camera/imu", IMU_QOS)
    probe.collect(Image, "/camera/image")
    graph = SdsGraphRun("camera.yaml", "--set", f"camera.source={clip}", "--set",
                        "camera.rate=8.0")
    assert graph.wait(timeout=60) == 0, graph.output()
    assert "has no camera IMU" in graph.output() and not messages


@pytest.mark.parametrize("video", [False, True])
def test_a_file_played_behind_real_time_says_so(clip, video):
    """1000 times real time: the frames' times run ahead of what decoding can give. Without
    packets every frame comes late; with them, the packets come late and the frames that
    could not be decoded in time are shed, counted: the frames no other frame refers to
    first, said on the console."""
    graph = SdsGraphRun("camera.yaml", "--set", f"camera.source={clip}",
                        "--set", "camera.rate=1000.0", "--set", "camera.repeat=10",
                        "--set", "camera.wait_for_subscribers=0",
                        "--set", f"camera.video={str(video).lower()}")
    assert graph.wait(timeout=120) == 0, graph.output()
    output = graph.output()
    if not video:
        assert "behind real time (reading and the graph need more CPU" in output
        assert "published 300 frames, up to" in output
        return
    # Reading packets is quick: the frames' 10 ms fall behind by what the decoder cannot do.
    counts = re.search(r"published (\d+) frames(?: \((\d+) more shed while decoding fell "
                       r"behind[^)]*\))? and the 300 video packets they came in", output)
    assert counts is not None, output
    shed = int(counts[2] or 0)
    assert int(counts[1]) + shed == 300, output
    assert ("decoding falls behind the camera" in output) == (shed > 0), output
    assert ("are not decoded until it catches up" in output) == (shed > 0), output
