"""ROS 2 node: the Arduino's serial line in; IMU, ToF and trigger/sync events out."""

from __future__ import annotations

import threading
from dataclasses import fields

import numpy as np
import serial
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from sds_arduino.clock import DeviceClock, camera_offset_s
from sds_arduino.protocol import Record
from sds_arduino.stream import RecordStream
from sds_ros.arduino_msg import TOPICS, SensorSpec, record_message
from sds_ros.hosted_node import HostedNode
from sensor_msgs.msg import Imu, Range

from sds_msgs.msg import SyncEvent

PARAMETERS = {"port": "/dev/ttyACM0", "baud": 115200,
              **{f.name: f.default for f in fields(SensorSpec)},
              "reconnect_period_s": 0.2, "stats_period_s": 5.0, "align_to_camera": True}
"""The node's parameters and defaults, the sensors' from `SensorSpec`
(config/params/arduino.yaml documents each)."""


class ArduinoBridgeNode(HostedNode):
    """Read the protocol-v1 line (pyserial), survive what a real port does, publish records.

    `imu` (sensor_msgs/Imu: linear acceleration [m/s²] with its covariance; orientation and
    angular velocity marked unknown, covariance[0] = -1), `tof` (sensor_msgs/Range [m]; NaN when
    the sensor flags the reading), `events` (sds_msgs/SyncEvent). Stamps are the device clock
    mapped onto the ROS clock (offset and drift, updated online) and, once the sync LED has
    been seen both commanded (LED record) and in the video (`camera_sync`), shifted onto the
    camera's clock so that IMU, ToF and frames line up (`align_to_camera`).
    """

    def __init__(self, node_name: str = "arduino", **node_kwargs) -> None:
        super().__init__(node_name, **node_kwargs)
        self._p = self.declare_parameter_table(PARAMETERS)
        self._spec = SensorSpec(**{f.name: self._p[f.name] for f in fields(SensorSpec)})
        reliable = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)
        self._publishers_by_topic = {
            "imu": self.create_publisher(Imu, "imu", reliable),
            "tof": self.create_publisher(Range, "tof", reliable),
            "events": self.create_publisher(SyncEvent, "events", reliable)}
        self.stream = RecordStream()
        self.clock_map = DeviceClock()
        self.published = 0
        self.reconnects = 0
        self._stop = threading.Event()
        self._sync_lock = threading.Lock()
        self._device_led_on: list[float] = []
        self._camera_led_on: list[float] = []
        self.camera_offset_s = float("nan")
        self.create_subscription(SyncEvent, "camera_sync", self._on_camera_sync, QoSProfile(
            depth=10, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self._reported: str | None = None
        self.create_timer(float(self._p["stats_period_s"]), self._report)
        self._thread = threading.Thread(target=self._read, name="serial", daemon=True)
        self._thread.start()

    def _read(self) -> None:
        """Serial thread: open, read, parse, publish; reopen after any port failure."""
        port = None
        while not self._stop.is_set():
            try:
                if port is None:
                    port = serial.Serial(self._p["port"], self._p["baud"], timeout=0.1)
                    self.get_logger().info(f"reading {self._p['port']}")
                data = port.read(4096)
            except (serial.SerialException, OSError) as error:
                if port is not None:
                    self.get_logger().warning(f"{self._p['port']}: {error}; reconnecting")
                    port.close()
                    port = None
                    self.stream.reset()
                    self.reconnects += 1
                self._stop.wait(float(self._p["reconnect_period_s"]))
                continue
            if data:
                now_s = self.get_clock().now().nanoseconds * 1e-9
                for record in self.stream.feed(data):
                    self._publish(record, now_s)
        if port is not None:
            port.close()

    def _on_camera_sync(self, msg: SyncEvent) -> None:
        """A sync-LED switch seen in the video: the camera's clock against the device's."""
        if msg.kind == SyncEvent.KIND_LED_ON:
            with self._sync_lock:
                self._camera_led_on.append(Time.from_msg(msg.header.stamp).nanoseconds * 1e-9)
                self._align()

    def _align(self) -> None:
        offset = camera_offset_s(self._device_led_on, self._camera_led_on)
        if self._p["align_to_camera"] and np.isfinite(offset) and offset != self.camera_offset_s:
            self.camera_offset_s = offset
            self.get_logger().info(f"stamps on the camera's clock: LED offset {offset:+.4f} s")

    def _publish(self, record: Record, received_s: float) -> None:
        device_s = self.clock_map.device_seconds(record.t_us)
        self.clock_map.observe(device_s, received_s)
        host_s = self.clock_map.to_host(device_s)
        with self._sync_lock:
            if record.kind == "LED" and record.values[0]:
                self._device_led_on.append(host_s)
                self._align()
            if np.isfinite(self.camera_offset_s):
                host_s += self.camera_offset_s
        stamp = Time(nanoseconds=round(host_s * 1e9)).to_msg()
        msg = record_message(record, stamp, round(device_s * 1e6), self._spec)
        self._publishers_by_topic[TOPICS[record.kind]].publish(msg)
        self.published += 1

    def summary(self) -> str:
        """One line: what was published and rejected."""
        s = self.stream.stats
        reasons = ", ".join(f"{k}: {v}" for k, v in sorted(s.reasons.items()))
        return (f"records {s.records}, published {self.published}, bad lines {s.bad_lines}, "
                f"noise bytes {s.noise_bytes}, missing records {s.missing_records}, "
                f"reconnects {self.reconnects}" + (f" ({reasons})" if reasons else ""))

    def _report(self) -> None:
        summary = self.summary()
        if summary != self._reported:
            self.get_logger().info(summary)
            self._reported = summary

    def close(self) -> None:
        """Stop reading; the last counts go to the log."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.get_logger().info(f"final: {self.summary()}")


def main(args: list[str] | None = None) -> None:
    """Run the node alone in this process."""
    from sds_ros.node_host import run_nodes

    raise SystemExit(run_nodes([(ArduinoBridgeNode, "arduino", False)], args))
