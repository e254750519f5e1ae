"""The bridge node as a real process reading a pseudo-terminal: the simulator's Arduino
streams with injected faults and an unplug/replug; every valid record published, bad ones
counted exactly."""

from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_helpers import LATCHED, Probe, SdsGraphRun, wait_until
from sds_arduino.protocol import format_record
from sds_ros.qos import stream_qos
from sds_sim.arduino import arduino_records
from sds_sim.scenario import load_scenario
from sensor_msgs.msg import Imu, Range

from sds_msgs.msg import SyncEvent

pytestmark = pytest.mark.ros

DEEP = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)
NOISE = b"\x00\xff#garbage%\x07"


def test_bridge_publishes_every_valid_record_through_a_pty(repo: Path, tmp_path: Path) -> None:
    scenario = load_scenario(repo / "config" / "scenarios" / "ground_kick.yaml",
                             {"duration_s": 3.0})
    records = arduino_records(scenario)
    rng = np.random.default_rng(11)
    lines, valid, bad, noise = [], [], 0, 0
    for record in records:
        text = format_record(record).encode()
        if rng.random() < 0.05:                 # a corrupted copy first: bad checksum
            lines.append(text.replace(b",", b";", 1))
            bad += 1
        if rng.random() < 0.05:                 # noise glued before the record
            text = NOISE + text
            noise += len(NOISE)
        lines.append(text)
        valid.append(record)
    disconnect_at = len(lines) // 2
    cut = lines[disconnect_at]                  # half written, then unplugged
    if cut.startswith(NOISE):
        noise -= len(NOISE)
    valid_cut = [r for r in valid if format_record(r).encode() in cut]
    valid = [r for r in valid if r not in valid_cut]
    bad += 1
    (tmp_path / "lines.bin").write_bytes(b"".join(lines))
    link = tmp_path / "ttyARDUINO"
    writer = subprocess.Popen([sys.executable, str(Path(__file__).with_name("arduino_writer.py")),
                               str(link), str(tmp_path / "lines.bin"), str(disconnect_at)],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert writer.stdout.readline().strip() == "READY"
    probe = Probe("arduino_probe")
    imu = probe.collect(Imu, "/arduino/imu", DEEP)
    tof = probe.collect(Range, "/arduino/tof", DEEP)
    events = probe.collect(SyncEvent, "/arduino/events", DEEP)
    graph = SdsGraphRun("arduino.yaml", "--set", f"arduino.port={link}",
                        "--set", "arduino.stats_period_s=0.5")
    try:
        assert wait_until(lambda: all(probe.node.count_publishers(t) for t in (
            "/arduino/imu", "/arduino/tof", "/arduino/events"))), graph.output()
        graph.wait_for_line("reading", timeout=30)
        camera_sync = probe.node.create_publisher(SyncEvent, "/camera/sync", LATCHED)
        assert wait_until(lambda: camera_sync.get_subscription_count() > 0), graph.output()
        camera_led = SyncEvent(kind=SyncEvent.KIND_LED_ON, source="camera")
        camera_led.header.stamp.sec = 1234     # the video's clock: far from the ROS clock
        camera_sync.publish(camera_led)
        time.sleep(0.5)
        writer.stdin.write("GO\n")
        writer.stdin.flush()
        assert writer.stdout.readline().strip() == "RECONNECTED"
        assert writer.stdout.readline().strip() == "DONE"
        expected = sum(1 for r in valid if r.kind == "IMU")
        assert wait_until(lambda: len(imu) >= expected, timeout=30), (len(imu), expected)
        time.sleep(1.0)
        # A subscriber that comes after the records (a recorder on a busy machine) gets them.
        late = probe.collect(Imu, "/arduino/imu", stream_qos(5000))
        assert wait_until(lambda: len(late) >= expected, timeout=10), (len(late), expected)
    finally:
        probe.close()
        graph.stop()
        writer.communicate("EXIT\n", timeout=10)
    kinds = {kind: [r for r in valid if r.kind == kind] for kind in ("IMU", "TOF")}
    assert [m.header.stamp for m in late] == [m.header.stamp for m in imu]
    assert len(imu) == len(kinds["IMU"]) and len(tof) == len(kinds["TOF"])
    assert len(events) == len(valid) - len(kinds["IMU"]) - len(kinds["TOF"])
    for msg, record in zip(imu, kinds["IMU"], strict=True):
        assert [msg.linear_acceleration.x, msg.linear_acceleration.y,
                msg.linear_acceleration.z] == pytest.approx(
            [v * 9.80665e-3 for v in record.values])
        assert msg.orientation_covariance[0] == -1.0
    for msg, record in zip(tof, kinds["TOF"], strict=True):
        assert msg.range == pytest.approx(record.values[0] * 1e-3)
    led_on = [e for e in events if e.kind == SyncEvent.KIND_LED_ON]
    assert len(led_on) == 1 and led_on[0].header.stamp.sec == 1234
    assert led_on[0].header.stamp.nanosec < 1000   # the device's LED switch is the camera's
    assert "LED offset" in graph.output()
    stamps = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in imu])
    device = np.array([r.t_us for r in kinds["IMU"]]) * 1e-6
    intervals = np.diff(stamps) - np.diff(device) / (1 + scenario.arduino.clock_drift_ppm * 1e-6)
    # On the camera's clock from the first record on (held until the LED linked the clocks),
    # never back; one jump, forward: the replug (the writer paused 2 s there, which its
    # device times do not show).
    assert np.all(np.diff(stamps) > 0)
    assert np.median(np.abs(intervals)) < 1e-4
    assert np.sum(np.abs(intervals) > 0.1) == 1 and intervals.max() > 1.0
    led_record = next(r for r in valid if r.kind == "LED" and r.values[0])
    first_before_led_s = (led_record.t_us - kinds["IMU"][0].t_us) * 1e-6
    assert abs(stamps[0] - (1234 - first_before_led_s)) < 0.01
    final = re.search(r"final: records (\d+), published (\d+), bad lines (\d+), noise bytes "
                      r"(\d+), missing records (\d+), reconnects (\d+)", graph.output())
    assert final, graph.output()
    records_seen, published, bad_seen, noise_seen, _, reconnects = map(int, final.groups())
    assert (records_seen, published, bad_seen, noise_seen, reconnects) == (
        len(valid), len(valid), bad, noise, 1), graph.output()
