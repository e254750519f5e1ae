"""ROS 2 node: the Arduino's serial line in; IMU, ToF and trigger/sync events out."""

from __future__ import annotations

import math
import threading

import serial
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from sensor_msgs.msg import Imu, Range

from sds_arduino.clock import DeviceClock
from sds_arduino.protocol import Record
from sds_arduino.stream import RecordStream
from sds_msgs.msg import SyncEvent

STANDARD_GRAVITY = 9.80665
EVENT_KINDS = {("TRG", 1): SyncEvent.KIND_TRIGGER, ("TRG", 0): SyncEvent.KIND_TRIGGER,
               ("LED", 1): SyncEvent.KIND_LED_ON, ("LED", 0): SyncEvent.KIND_LED_OFF,
               ("LAS", 1): SyncEvent.KIND_LASERS_ON, ("LAS", 0): SyncEvent.KIND_LASERS_OFF}


class ArduinoBridgeNode(Node):
    """Read the protocol-v1 line (pyserial), survive what a real port does, publish records.

    `imu` (sensor_msgs/Imu: linear acceleration [m/s²] with its covariance; orientation and
    angular velocity marked unknown, covariance[0] = -1), `tof` (sensor_msgs/Range [m]; NaN when
    the sensor flags the reading), `events` (sds_msgs/SyncEvent). Stamps are the device clock
    mapped onto the ROS clock (offset and drift, updated online).
    """

    def __init__(self, node_name: str = "arduino", **node_kwargs) -> None:
        super().__init__(node_name, **node_kwargs)
        self.finished = threading.Event()
        self.exit_code = 0
        for name, default in (("port", "/dev/ttyACM0"), ("baud", 115200),
                              ("frame_id", "arduino"), ("accel_noise_mg", 8.0),
                              ("tof_noise_mm", 1.0), ("tof_field_of_view_rad", 0.44),
                              ("tof_min_range_m", 0.03), ("tof_max_range_m", 2.0),
                              ("reconnect_period_s", 0.2), ("stats_period_s", 5.0)):
            self.declare_parameter(name, default)
        self._p = {name: self.get_parameter(name).value for name in
                   ("port", "baud", "frame_id", "accel_noise_mg", "tof_noise_mm",
                    "tof_field_of_view_rad", "tof_min_range_m", "tof_max_range_m",
                    "reconnect_period_s", "stats_period_s")}
        reliable = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)
        self._imu_pub = self.create_publisher(Imu, "imu", reliable)
        self._tof_pub = self.create_publisher(Range, "tof", reliable)
        self._event_pub = self.create_publisher(SyncEvent, "events", reliable)
        self.stream = RecordStream()
        self.clock_map = DeviceClock()
        self.published = 0
        self.reconnects = 0
        self._stop = threading.Event()
        self._reported = None
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

    def _publish(self, record: Record, received_s: float) -> None:
        device_s = self.clock_map.device_seconds(record.t_us)
        self.clock_map.observe(device_s, received_s)
        stamp = Time(nanoseconds=round(self.clock_map.to_host(device_s) * 1e9)).to_msg()
        if record.kind == "IMU":
            msg = Imu()
            msg.header.stamp, msg.header.frame_id = stamp, self._p["frame_id"]
            a = [v * STANDARD_GRAVITY * 1e-3 for v in record.values]
            msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z = a
            variance = (self._p["accel_noise_mg"] * STANDARD_GRAVITY * 1e-3) ** 2
            msg.linear_acceleration_covariance = [variance, 0.0, 0.0, 0.0, variance, 0.0,
                                                  0.0, 0.0, variance]
            msg.orientation_covariance[0] = -1.0
            msg.angular_velocity_covariance[0] = -1.0
            self._imu_pub.publish(msg)
        elif record.kind == "TOF":
            range_mm, status = record.values
            msg = Range(radiation_type=Range.INFRARED,
                        field_of_view=float(self._p["tof_field_of_view_rad"]),
                        min_range=float(self._p["tof_min_range_m"]),
                        max_range=float(self._p["tof_max_range_m"]),
                        range=range_mm * 1e-3 if status == 0 else math.nan)
            msg.variance = (self._p["tof_noise_mm"] * 1e-3) ** 2
            msg.header.stamp, msg.header.frame_id = stamp, self._p["frame_id"]
            self._tof_pub.publish(msg)
        else:
            msg = SyncEvent(kind=EVENT_KINDS[(record.kind, int(record.values[0] != 0))],
                            source="arduino", device_time_us=round(device_s * 1e6),
                            sequence=record.seq)
            msg.header.stamp, msg.header.frame_id = stamp, self._p["frame_id"]
            self._event_pub.publish(msg)
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
    from sds_bringup.node_host import run_nodes

    raise SystemExit(run_nodes([(ArduinoBridgeNode, "arduino", False)], args))
