"""The chain's stream QoS and start-up wait, on a real rclpy node over Fast DDS."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
import xml.etree.ElementTree as ElementTree

import pytest
from ros_helpers import RELIABLE, Probe, wait_until
from sds_bringup.ros_env import graph_environment
from sds_ros.qos import start_when_consumed, stream_qos, wait_for_acks
from std_msgs.msg import Header, String

pytestmark = pytest.mark.ros


def test_a_stream_reader_that_joins_late_gets_the_first_messages():
    """What a writer sent before a reader matched reaches that reader (the recorder's case)."""
    probe = Probe("qos_probe")
    try:
        publisher = probe.node.create_publisher(Header, "/qos_test/late", stream_qos(10))
        for index in range(12):
            publisher.publish(Header(frame_id=str(index)))
        late = probe.collect(Header, "/qos_test/late", stream_qos(10))
        volatile = probe.collect(Header, "/qos_test/late", RELIABLE)
        assert wait_until(lambda: len(late) == 10, timeout=10)
        time.sleep(0.2)
    finally:
        probe.close()
    assert [m.frame_id for m in late] == [str(i) for i in range(2, 12)]   # the last `depth`
    assert volatile == []   # a volatile reader gets none of them: what the stream QoS avoids


def test_inputs_start_once_every_output_has_its_consumers():
    probe = Probe("qos_probe")
    started: list[float] = []
    try:
        points = probe.node.create_publisher(Header, "/qos_test/points", stream_qos())
        fits = probe.node.create_publisher(Header, "/qos_test/fits", stream_qos())
        start_when_consumed(probe.node, [(points, 1), (fits, 2)],
                            lambda: started.append(time.monotonic()))
        probe.collect(Header, "/qos_test/points", stream_qos())
        probe.collect(Header, "/qos_test/fits", stream_qos())
        time.sleep(0.5)
        assert started == []   # the fits have one consumer of two
        probe.collect(Header, "/qos_test/fits", stream_qos())
        assert wait_until(lambda: started, timeout=10)
        time.sleep(0.3)
        assert len(started) == 1   # once
        nothing_wanted: list[int] = []
        start_when_consumed(probe.node, [(points, 0)], lambda: nothing_wanted.append(1))
        assert nothing_wanted == [1]   # at once
    finally:
        probe.close()


def test_graph_processes_load_the_fast_dds_profile_with_a_quick_heartbeat():
    """The graph environment names a valid profiles file; rclpy loads it without an error."""
    environment = graph_environment(7)
    profiles = environment["FASTDDS_DEFAULT_PROFILES_FILE"]
    period = ElementTree.parse(profiles).find(".//{*}data_writer/{*}times/{*}heartbeat_period")
    assert (int(period.find("{*}sec").text), int(period.find("{*}nanosec").text)) == (0, 10**8)
    script = ("import rclpy; from rclpy.node import Node; from std_msgs.msg import Header; "
              "rclpy.init(); Node('profile_check').create_publisher(Header, 'x', 10)")
    done = subprocess.run([sys.executable, "-c", script], env=environment, capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0 and "XMLPARSER" not in done.stdout + done.stderr, done.stderr


ACK_READER = """
import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import String
rclpy.init()
node = Node("ack_reader")
node.create_subscription(String, "/qos_test/acks", lambda msg: None,
                         QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
rclpy.spin(node)
"""


def test_waiting_for_a_stopped_readers_acks_freezes_nothing_and_ends_on_stop_or_timeout():
    """The frame source's and player's end-of-stream wait: a reader that stopped acknowledging
    (SIGSTOP) neither freezes the waiting process's other threads nor outlasts the stop."""
    probe = Probe("qos_probe")
    reader = subprocess.Popen([sys.executable, "-c", ACK_READER], env=dict(os.environ))
    try:
        publisher = probe.node.create_publisher(String, "/qos_test/acks", RELIABLE)
        assert wait_until(lambda: publisher.get_subscription_count() == 1, timeout=30)
        publisher.publish(String(data="first"))
        assert wait_for_acks(publisher, 10.0, threading.Event())
        os.kill(reader.pid, signal.SIGSTOP)
        publisher.publish(String(data="x" * 100_000))
        stop, result = threading.Event(), []
        waiter = threading.Thread(
            target=lambda: result.append(wait_for_acks(publisher, 30.0, stop)))
        start = time.monotonic()
        waiter.start()
        time.sleep(0.5)
        # rclpy's own wait_for_all_acked(30 s) would hold the GIL: this sleep would last 30 s.
        assert time.monotonic() - start < 2.0 and waiter.is_alive()
        stop.set()
        waiter.join(timeout=2.0)
        assert result == [False] and time.monotonic() - start < 3.0
        start = time.monotonic()
        assert not wait_for_acks(publisher, 0.3, threading.Event())
        assert 0.3 <= time.monotonic() - start < 1.5
    finally:
        reader.kill()
        reader.wait(timeout=10)
        probe.close()
