"""Recorder and player as real processes: record, play back, record again; crash safety."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap_ros2.reader import read_ros2_messages
from ros_helpers import LATCHED, RELIABLE, Probe, SdsGraphRun, wait_until
from rosbags.highlevel import AnyReader
from sds_record.mcap_files import read_messages, recorded_topics
from std_msgs.msg import Header

from sds_msgs.msg import CameraModel, SyncEvent

pytestmark = pytest.mark.ros

TOPICS = ("/test/header", "/test/sync", "/test/model")



def publish_stream(probe: Probe, seconds: float, rate_hz: float) -> list[float]:
    """Header and SyncEvent at `rate_hz`, one latched CameraModel; the send times [s]."""
    headers = probe.node.create_publisher(Header, "/test/header", RELIABLE)
    events = probe.node.create_publisher(SyncEvent, "/test/sync", RELIABLE)
    model = probe.node.create_publisher(CameraModel, "/test/model", LATCHED)
    assert wait_until(lambda: headers.get_subscription_count() and events.get_subscription_count()
                      and model.get_subscription_count())
    model.publish(CameraModel(model_type="scaramuzza", full_width=3840, full_height=2160))
    sent = []
    for index in range(int(seconds * rate_hz)):
        stamp = probe.node.get_clock().now().to_msg()
        headers.publish(Header(stamp=stamp, frame_id=f"frame {index}"))
        events.publish(SyncEvent())
        sent.append(time.monotonic())
        time.sleep(1.0 / rate_hz)
    return sent


def by_topic(path: Path) -> dict[str, list]:
    result: dict[str, list] = {}
    for message in read_messages(path):
        result.setdefault(message.topic, []).append(message)
    return result


def test_record_play_record_gives_the_same_messages(tmp_path: Path) -> None:
    first, second = tmp_path / "first.mcap", tmp_path / "second.mcap"
    recorder = SdsGraphRun("record.yaml", "--set", f"recorder.output={first}",
                           "--set", f"recorder.topics={list(TOPICS)}")
    probe = Probe("record_probe")
    try:
        publish_stream(probe, 2.0, 20.0)
        time.sleep(0.5)
    finally:
        probe.close()
        recorder.stop()
    assert recorder.popen.returncode == 128 + signal.SIGTERM, recorder.output()
    assert "[recorder] exited with code 0" in recorder.output()
    assert recorded_topics(first) == {"/test/header": ("std_msgs/msg/Header", False),
                                      "/test/sync": ("sds_msgs/msg/SyncEvent", False),
                                      "/test/model": ("sds_msgs/msg/CameraModel", True)}

    recorder = SdsGraphRun("record.yaml", "--set", f"recorder.output={second}",
                           "--set", f"recorder.topics={list(TOPICS)}")
    player = SdsGraphRun("play.yaml", "--set", f"player.input={first}")
    try:
        assert player.wait(timeout=60) == 0, player.output()
        time.sleep(0.5)
    finally:
        player.stop()
        recorder.stop()
    original, again = by_topic(first), by_topic(second)
    assert {t: len(m) for t, m in original.items()} == {
        "/test/header": 40, "/test/sync": 40, "/test/model": 1}
    # The player sends each message at its log time's offset in the first recording; the
    # second recording's publish times are those sends (the DDS source timestamps), so they
    # measure the player's pacing. (Its log times are when the recorder received them: a
    # busy moment of the recorder's once put them 11 ms behind over the 2 s.) Five runs on the
    # 2-core machine: median 0.10-0.21 ms, largest 0.32-1.30 ms; the bounds leave a loaded
    # machine's late wake-ups room.
    origin = min(m.log_time_ns for messages in original.values() for m in messages)
    origin_again = min(m.publish_time_ns for messages in again.values() for m in messages)
    for topic, messages in original.items():
        assert [m.data for m in again[topic]] == [m.data for m in messages], topic
        offsets = [(m.log_time_ns - origin) * 1e-9 for m in messages]
        offsets_again = [(m.publish_time_ns - origin_again) * 1e-9 for m in again[topic]]
        differences = np.abs(np.subtract(offsets_again, offsets))
        assert np.median(differences) < 0.005 and differences.max() < 0.05, (topic, differences)
    stamps = [m.ros_msg.stamp for m in read_ros2_messages(second)
              if m.channel.topic == "/test/header"]
    assert [s.sec * 10**9 + s.nanosec for s in stamps] == [
        s.sec * 10**9 + s.nanosec for s in (m.ros_msg.stamp for m in read_ros2_messages(first)
                                            if m.channel.topic == "/test/header")]
    with AnyReader([second]) as reader:
        decoded = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()]
    assert len(decoded) == 81
    assert any(getattr(d, "model_type", "") == "scaramuzza" for d in decoded)


def test_sigkill_loses_at_most_the_last_second_and_repair_restores_the_index(
        tmp_path: Path) -> None:
    output = tmp_path / "killed.mcap"
    recorder = SdsGraphRun("record.yaml", "--set", f"recorder.output={output}",
                           "--set", f"recorder.topics={list(TOPICS)}")
    probe = Probe("kill_probe")
    try:
        sent = publish_stream(probe, 3.0, 50.0)
        started = recorder.wait_for_line("[recorder] started (pid ", timeout=5)
        pid = int(started.split("(pid ")[1].split(")")[0])
        os.kill(pid, signal.SIGKILL)
        killed_at = time.monotonic()
    finally:
        probe.close()
        recorder.stop()
    survived = [m for m in read_messages(output) if m.topic == "/test/header"]
    old_enough = sum(1 for t in sent if t < killed_at - 1.0)
    assert len(survived) >= old_enough, (len(survived), old_enough, len(sent))

    repaired = tmp_path / "repaired.mcap"
    done = subprocess.run([str(Path(sys.executable).with_name("sds")), "mcap-repair",
                           str(output), str(repaired)], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0 and "had no summary" in done.stdout, done.stdout + done.stderr
    frames = [m.ros_msg.frame_id for m in read_ros2_messages(repaired)
              if m.channel.topic == "/test/header"]
    assert frames == [f"frame {i}" for i in range(len(survived))]
    with AnyReader([repaired]) as reader:
        assert reader.message_count == len(list(read_messages(output)))
