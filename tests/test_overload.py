"""A chain behind its camera sheds the live previews, says so, and keeps every recorded result."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
import yaml
from builtin_interfaces.msg import Time
from rcl_interfaces.msg import Log
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_helpers import LATCHED, RELIABLE, Probe, SdsGraphRun, wait_until
from sds_model.rig import load_rig
from sds_nodes.viewer import ViewerNode
from sds_record.mcap_files import header_stamp_ns, not_recorded, read_messages
from sds_ros.frame_gaps import FrameGaps
from sds_ros.image_msg import image_to_msg
from sds_ros.qos import live_qos, stream_qos
from sds_ros.shedding import NEW_OFFSET_MESSAGES, REPORT_PERIOD_S, LiveShedding
from sensor_msgs.msg import Image, PointCloud2
from std_msgs.msg import Header

from sds_msgs.msg import CameraModel, LaserSpot, LaserSpotArray


def test_shedding_counts_late_frames_against_the_fastest_and_says_so():
    shedding = LiveShedding("points_live", max_lag_s=0.1)
    # Stamps on another clock: a constant 100 s offset is no lateness.
    assert all(shedding.keep(100.0 + jitter) for jitter in (0.02, 0.0, 0.05, 0.01))
    assert shedding.report(0.0) is None
    assert not shedding.keep(100.5) and not shedding.keep(100.3)
    assert shedding.keep(100.08)
    started = shedding.report(1.0)
    assert started is not None and "shedding the frames more than 100 ms late" in started
    assert "up to 0.50 s" in started
    for _ in range(8):
        shedding.keep(101.0)
    assert shedding.report(2.0) is None          # within the report period: quiet
    summary = shedding.report(1.0 + REPORT_PERIOD_S)
    assert summary is not None and "shed 8 of 8 frames" in summary
    shedding.keep(100.01)
    assert shedding.report(12.0) is None          # back in time only after a quiet period
    ended = shedding.report(11.0 + REPORT_PERIOD_S)
    assert ended is not None and "back in time, 10 frames shed over 10.0 s" in ended
    assert shedding.report(22.0) is None


def test_a_step_of_the_clock_while_a_message_waits_does_not_make_the_rest_late():
    """The system clock stepped back 5 s while one message was on its way: that one is kept,
    and the messages after it, on time, are not shed. A publisher whose clock stays 5 s
    behind from then on sets the new shortest wait after NEW_OFFSET_MESSAGES."""
    shedding = LiveShedding("spots_live", max_lag_s=0.1)
    assert all(shedding.keep(wait) for wait in (0.02, 0.01, 0.03))
    assert shedding.keep(0.01 - 5.0)                       # the step
    assert all(shedding.keep(wait) for wait in (0.02, 0.01, 0.05, 0.03))
    assert not shedding.keep(0.5)                          # still sheds what is late
    behind = [shedding.keep(0.02 - 5.0) for _ in range(NEW_OFFSET_MESSAGES)]
    assert all(behind)
    assert shedding.baseline_s == pytest.approx(0.02 - 5.0)
    assert not shedding.keep(0.02 - 5.0 + 0.5)             # late against the new offset
    assert shedding.keep(0.03 - 5.0)


BURST = 60
"""Frames published at once to the reconstruction node."""
ROSOUT = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
"""Every node's console lines as /rosout carries them."""


@pytest.mark.ros
def test_recon_behind_its_input_sheds_live_points_and_keeps_every_recorded_frame(repo):
    rig_file = repo / "config" / "rigs" / "stelium.yaml"
    rig = load_rig(rig_file)
    pixels = rig.project(np.array([[d.emitter_mm[0], d.emitter_mm[1], 0.0]
                                   for d in rig.diodes]))
    probe = Probe("overload_probe")
    # A 10 ms limit: a burst of frames puts the node behind its input within a few frames; the
    # live cloud is checked on frames one at a time, not on the burst's first, whose delivery
    # alone can take milliseconds on a busy machine.
    graph = SdsGraphRun("recon.yaml", "--set", f"recon.rig={rig_file}",
                        "--set", "recon.live_max_lag_s=0.01")
    try:
        live = probe.collect(PointCloud2, "/recon/points_live", live_qos())
        clouds = probe.collect(PointCloud2, "/recon/points", stream_qos())
        live_pub = probe.node.create_publisher(LaserSpotArray, "/tracker/spots_live",
                                               live_qos())
        spots_pub = probe.node.create_publisher(LaserSpotArray, "/tracker/spots", stream_qos())
        assert wait_until(lambda: live_pub.get_subscription_count() > 0
                          and spots_pub.get_subscription_count() > 0), graph.output()

        def frame(index: int) -> LaserSpotArray:
            return LaserSpotArray(header=Header(stamp=Time(sec=index)), frame_index=index,
                                  spots=[LaserSpot(laser_id=d.laser_id, x_px=x, y_px=y,
                                                   sigma_px=0.05)
                                         for d, (x, y) in zip(rig.diodes, pixels, strict=True)])

        def on_time(first: int) -> bool:
            """Frames one at a time, until the best-effort live cloud has matched the probe."""
            live.clear()
            for index in range(first, first + 100):
                live_pub.publish(frame(index))
                if wait_until(lambda: bool(live), 0.05):
                    return True
            return False

        assert on_time(1000), graph.output()
        live.clear()
        # A burst: each waits for the triangulation and fits of those before it.
        for index in range(BURST):
            live_pub.publish(frame(index))
            spots_pub.publish(frame(index))
        assert wait_until(lambda: len(clouds) == BURST), graph.output()
        graph.wait_for_line("points_live: shedding the frames more than 10 ms late", 10.0)
        shed_burst = BURST - len(live)
        # On time again, the live cloud is made again.
        back = on_time(2000)
    finally:
        probe.close()
        graph.stop()
    # Every frame's recorded cloud came; most of the burst's live ones were shed.
    assert sorted(m.header.stamp.sec for m in clouds) == list(range(BURST))
    assert shed_burst >= BURST // 2
    assert back


def test_frame_gaps_count_the_frames_between_two_stamps():
    gaps = FrameGaps()
    stamps = [100.0 + k / 30 + (0.002 if k % 2 else 0.0) for k in range(40)]
    del stamps[25:28]   # three frames never came
    del stamps[10]      # and one more, before the period is known: not counted
    missing = [gaps.missed(t) for t in stamps]
    assert sum(missing) == 3 and missing[24] == 3
    assert gaps.missed(5.0) == 0 and gaps.missed(5.1) == 0   # a new stream: period relearnt


@pytest.mark.ros
def test_the_tracker_numbers_frames_by_their_stamps_and_says_which_never_came(repo, tmp_path):
    rig_file = repo / "config" / "rigs" / "stelium.yaml"
    graph_file = tmp_path / "tracker.yaml"
    graph_file.write_text(yaml.safe_dump({"nodes": [{
        "name": "tracker", "plugin": "sds_nodes.tracker:TrackerNode",
        "params": str(repo / "config" / "params" / "tracker.yaml"),
        "parameters": {"rig": str(rig_file)},
        "remap": {"image": "/camera/image", "camera_model": "/camera/camera_model",
                  "spots": "/tracker/spots", "frame_ack": "/camera/frame_ack"}}]}))
    probe = Probe("gaps_probe")
    graph = SdsGraphRun(str(graph_file))
    try:
        spots = probe.collect(LaserSpotArray, "/tracker/spots", stream_qos())
        acks = probe.collect(Header, "/camera/frame_ack", RELIABLE)
        model_pub = probe.node.create_publisher(CameraModel, "/camera/camera_model", LATCHED)
        image_pub = probe.node.create_publisher(Image, "/camera/image", RELIABLE)
        assert wait_until(lambda: image_pub.get_subscription_count() > 0), graph.output()
        model_pub.publish(CameraModel(channel="red", full_width=3840, full_height=2160))
        time.sleep(1.0)   # a volatile reader just matched can miss what comes at once
        image = np.zeros((64, 64), np.uint8)
        sent = [k for k in range(40) if not 25 <= k < 28]   # frames 25-27 never sent
        for k in sent:   # each once the tracker has taken the one before (its ack)
            stamp = Time(sec=1000 + k // 30, nanosec=round(k % 30 / 30 * 1e9))
            image_pub.publish(image_to_msg(image, stamp, "camera_optical"))
            assert wait_until(lambda stamp=stamp: acks and acks[-1].stamp == stamp, 20.0), \
                graph.output()
        graph.wait_for_line("3 frame(s) missing before frame 28, 3 in all", 15.0)
        # The Hampel window's last frames come after 1 s without a frame.
        assert wait_until(lambda: len(spots) == len(sent), 15.0), graph.output()
    finally:
        probe.close()
        graph.stop()
    assert [m.frame_index for m in spots] == sent


@pytest.mark.ros
def test_a_live_viewer_behind_its_images_sheds_them_and_says_so(tmp_path):
    """The viewer's executor held for a second (a callback that took long, a busy machine)
    while the camera goes on at 30 fps: its reader keeps the newest 5 images (sensor-data
    QoS), the oldest of which waited 4 frame periods (133 ms) or more, beyond its 50 ms
    limit; it sheds them and says so on /rosout, and once it keeps up again it says that too.
    (The test holds the executor, not the process: a viewer process stopped with SIGSTOP
    sometimes got no late image after it resumed, a flake of how the middleware delivers to a
    stopped process, not of the viewer.)"""
    probe = Probe("viewer_shedding_probe")
    said = probe.collect(Log, "/rosout", ROSOUT)
    viewer = ViewerNode("viewer", context=probe.context, parameter_overrides=[
        Parameter("output", value=str(tmp_path / "live.rrd")), Parameter("live", value=True),
        Parameter("live_max_lag_s", value=0.05)])
    executor = SingleThreadedExecutor(context=probe.context)
    executor.add_node(viewer)
    held, done = threading.Event(), threading.Event()

    def spin() -> None:
        while not done.is_set():
            if held.is_set():
                time.sleep(0.01)
            else:
                executor.spin_once(timeout_sec=0.01)

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    try:
        image_pub = probe.node.create_publisher(Image, "/image", RELIABLE)   # viewer's "image"
        assert wait_until(lambda: image_pub.get_subscription_count() > 0)
        message = image_to_msg(np.full((48, 64), 50, np.uint8), Time(sec=0), "camera")

        def publish(first: int, count: int) -> None:
            for index in range(first, first + count):   # at 30 fps
                message.header.stamp = Time(sec=index)
                image_pub.publish(message)
                time.sleep(1 / 30)

        def viewer_said(text: str) -> Log | None:
            return next((log for log in said if log.name == "viewer" and text in log.msg),
                        None)

        publish(0, 15)
        held.set()
        try:
            publish(15, 30)
        finally:
            held.clear()
        publish(45, 15)
        assert wait_until(lambda: viewer_said("shedding the frames more than 50 ms late"),
                          10.0), [log.msg for log in said]
        started = viewer_said("shedding the frames")
        assert started is not None and started.level == Log.WARN
        assert "the recorded measurements are complete" in started.msg
        assert viewer_said("back in time") is None
        publish(60, 30 * int(REPORT_PERIOD_S + 2))
        assert wait_until(lambda: viewer_said("back in time"), 5.0), [log.msg for log in said]
    finally:
        done.set()
        spinner.join(timeout=2.0)
        executor.shutdown(timeout_sec=2.0)
        viewer.close()
        viewer.destroy_node()
        probe.close()


@pytest.mark.ros
def test_the_recorder_says_how_many_messages_never_reached_it(tmp_path):
    output = tmp_path / "burst.mcap"
    recorder = SdsGraphRun("record.yaml", "--set", f"recorder.output={output}",
                           "--set", "recorder.topics=[/test/image]")
    probe = Probe("recorder_gaps_probe")
    try:
        # A writer that keeps one message: a burst outruns the recorder's writing.
        images = probe.node.create_publisher(Image, "/test/image", QoSProfile(
            depth=1, reliability=ReliabilityPolicy.RELIABLE))
        assert wait_until(lambda: images.get_subscription_count() > 0), recorder.output()
        recorder.wait_for_line("recording /test/image", 10.0)
        image = np.random.default_rng(0).integers(0, 255, (1080, 1920), np.uint8)
        # The first message alone, taken before the burst: the recorder counts what never
        # reached it from the first one it got, and a burst whose last message was the only
        # one taken left nothing to count (a flake).
        images.publish(image_to_msg(image, Time(sec=0), "camera"))
        time.sleep(1.0)
        for index in range(1, 60):
            images.publish(image_to_msg(image, Time(sec=index), "camera"))
        time.sleep(2.0)
    finally:
        probe.close()
        recorder.stop()
    recorded = [m for m in read_messages(output) if m.topic == "/test/image"]
    lost = 60 - len(recorded)
    assert lost > 0, "the burst did not outrun the recorder: the test proves nothing"
    said = recorder.wait_for_line("never reached the recorder, so not in it", 1.0)
    # Every frame after the first recorded one is either in the file or counted.
    first = min(header_stamp_ns(m.data) for m in recorded) // 10**9
    assert f"{60 - first - len(recorded)} of /test/image" in said, recorder.output()
    assert "never reached the recorder (it fell behind" in recorder.output()


@pytest.mark.ros
def test_what_was_published_before_the_recorder_subscribed_is_counted_in_its_file(tmp_path):
    """A publisher (an Arduino's bridge) that wrote before the recorder subscribed: what it
    wrote then is not in the recording, and the recording says how much (its closing
    metadata, `not_recorded`), as the recorder's log does."""
    output = tmp_path / "late.mcap"
    probe = Probe("late_recorder_probe")
    recorder = None
    try:
        records = probe.node.create_publisher(Header, "/test/records", QoSProfile(
            depth=100, reliability=ReliabilityPolicy.RELIABLE))
        for index in range(30):
            records.publish(Header(stamp=Time(sec=index)))
        recorder = SdsGraphRun("record.yaml", "--set", f"recorder.output={output}",
                               "--set", "recorder.topics=[/test/records]")
        assert wait_until(lambda: records.get_subscription_count() > 0), recorder.output()
        recorder.wait_for_line("recording /test/records", 10.0)
        time.sleep(0.5)
        for index in range(30, 50):
            records.publish(Header(stamp=Time(sec=index)))
        time.sleep(1.0)
    finally:
        probe.close()
        if recorder is not None:
            recorder.stop()
    recorded = [m for m in read_messages(output) if m.topic == "/test/records"]
    assert recorded, "nothing recorded: the test proves nothing"
    counted = not_recorded(output)
    assert counted.get("/test/records", 0) >= 30, counted
    assert len(recorded) + counted["/test/records"] == 50, (len(recorded), counted)
    said = recorder.wait_for_line("published before the recorder subscribed, so not in it", 1.0)
    assert f"{counted['/test/records']} of /test/records" in said, recorder.output()
