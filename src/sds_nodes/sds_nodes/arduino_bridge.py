"""ROS 2 node: the Arduino's serial line in; IMU, ToF and trigger/sync events out."""

from __future__ import annotations

import threading
from dataclasses import fields

import serial
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from sds_arduino.protocol import Record
from sds_arduino.stamps import HOLD_S, RecordStamper, StampClock, Stamped
from sds_arduino.stream import RecordStream
from sds_ros.arduino_msg import TOPICS, SensorSpec, record_message
from sds_ros.hosted_node import HostedNode
from sds_ros.qos import stream_qos
from sensor_msgs.msg import Imu, Range

from sds_msgs.msg import SyncEvent

PARAMETERS = {"port": "/dev/ttyACM0", "baud": 115200,
              **{f.name: f.default for f in fields(SensorSpec)},
              "reconnect_period_s": 0.2, "stats_period_s": 5.0, "align_to_camera": True,
              "hold_for_led_s": HOLD_S}
"""The node's parameters and defaults, the sensors' from `SensorSpec`
(config/params/arduino.yaml documents each)."""
RECORD_HISTORY = 2000
"""Records each topic keeps for a late subscriber, as the chain's streams do (`stream_qos`):
on a busy machine the recorder subscribed 5 s after the bridge had published the first
records, and a volatile writer's were lost to it. 10 s of the 200 Hz IMU."""


class ArduinoBridgeNode(HostedNode):
    """Read the protocol-v1 line (pyserial), survive what a real port does, publish records.

    `imu` (sensor_msgs/Imu: linear acceleration [m/s²] with its covariance; orientation and
    angular velocity marked unknown, covariance[0] = -1), `tof` (sensor_msgs/Range [m]; NaN when
    the sensor flags the reading), `events` (sds_msgs/SyncEvent). Stamps are the device clock
    mapped onto the ROS clock (offset and drift, updated online) and, once the sync LED has
    been seen both commanded (LED record) and in the video (`camera_sync`), shifted onto the
    camera's clock so that IMU, ToF and frames line up (`align_to_camera`). Records wait until
    both are known (at most `hold_for_led_s`), so that every stamp of a run is on one clock
    and none goes back (`sds_arduino.stamps`).
    """

    def __init__(self, node_name: str = "arduino", **node_kwargs) -> None:
        super().__init__(node_name, **node_kwargs)
        self._p = self.declare_parameter_table(PARAMETERS)
        self._spec = SensorSpec(**{f.name: self._p[f.name] for f in fields(SensorSpec)})
        kept = stream_qos(RECORD_HISTORY)
        self._publishers_by_topic = {
            "imu": self.create_publisher(Imu, "imu", kept),
            "tof": self.create_publisher(Range, "tof", kept),
            "events": self.create_publisher(SyncEvent, "events", kept)}
        self.stream = RecordStream()
        self.stamper: RecordStamper[tuple[Record, float]] = RecordStamper(
            bool(self._p["align_to_camera"]), hold_s=float(self._p["hold_for_led_s"]))
        self.published = 0
        self.reconnects = 0
        self._stop = threading.Event()
        self._stamp_lock = threading.Lock()   # the serial thread and the sync callback
        self._clock_said = StampClock.UNDECIDED
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
                    with self._stamp_lock:
                        self.stamper.new_session()
                    self.reconnects += 1
                self._stop.wait(float(self._p["reconnect_period_s"]))
                continue
            if data:
                now_s = self.get_clock().now().nanoseconds * 1e-9
                for record in self.stream.feed(data):
                    self._stamp(record, now_s)
        if port is not None:
            port.close()

    def _on_camera_sync(self, msg: SyncEvent) -> None:
        """A sync-LED switch seen in the video: the camera's clock against the device's."""
        if msg.kind == SyncEvent.KIND_LED_ON:
            with self._stamp_lock:
                self._publish(self.stamper.camera_led_on(
                    Time.from_msg(msg.header.stamp).nanoseconds * 1e-9))

    def _stamp(self, record: Record, received_s: float) -> None:
        """A record in: the records whose stamps are now known out."""
        with self._stamp_lock:
            device_s = self.stamper.clock_map.device_seconds(record.t_us)
            self._publish(self.stamper.add((record, device_s), device_s, received_s,
                                           led_on=record.kind == "LED" and record.values[0] > 0))

    def _publish(self, released: list[Stamped[tuple[Record, float]]]) -> None:
        """Released records, in order, on the run's one clock (said once when decided)."""
        if released and self.stamper.clock is not self._clock_said:
            self._clock_said = self.stamper.clock
            if self._clock_said is StampClock.CAMERA:
                self.get_logger().info("stamps on the camera's clock: LED offset "
                                       f"{self.stamper.camera_offset_s:+.4f} s")
            elif self._p["align_to_camera"]:
                self.get_logger().warning(
                    f"no sync LED seen within {self._p['hold_for_led_s']:g} s: this run's "
                    "Arduino stamps are on the host clock, not the camera's")
        for stamped in released:
            record, device_s = stamped.item
            stamp = Time(nanoseconds=round(stamped.stamp_s * 1e9)).to_msg()
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
        """Stop reading, publish what is held; the last counts go to the log."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        with self._stamp_lock:
            self._publish(self.stamper.flush())
        self.get_logger().info(f"final: {self.summary()}")


def main(args: list[str] | None = None) -> None:
    """Run the node alone in this process."""
    from sds_ros.node_host import run_nodes

    raise SystemExit(run_nodes([(ArduinoBridgeNode, "arduino", False)], args))
