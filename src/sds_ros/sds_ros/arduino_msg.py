"""Protocol records as ROS 2 messages (the bridge node and `sds import-sd` share these)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from builtin_interfaces.msg import Time
from sds_arduino.protocol import Record
from sensor_msgs.msg import Imu, Range

from sds_msgs.msg import SyncEvent
from sds_ros.static_tf import ARDUINO_FRAME

STANDARD_GRAVITY = 9.80665
EVENT_KINDS = {("TRG", 1): SyncEvent.KIND_TRIGGER, ("TRG", 0): SyncEvent.KIND_TRIGGER,
               ("LED", 1): SyncEvent.KIND_LED_ON, ("LED", 0): SyncEvent.KIND_LED_OFF,
               ("LAS", 1): SyncEvent.KIND_LASERS_ON, ("LAS", 0): SyncEvent.KIND_LASERS_OFF}
TOPICS = {"IMU": "imu", "TOF": "tof", "TRG": "events", "LED": "events", "LAS": "events"}
"""Relative topic of each record kind."""


@dataclass(frozen=True)
class SensorSpec:
    """What the messages say about the sensors: frame, noise, ToF cone and limits."""

    frame_id: str = ARDUINO_FRAME
    accel_noise_mg: float = 8.0
    tof_noise_mm: float = 1.0
    tof_field_of_view_rad: float = 0.44
    tof_min_range_m: float = 0.03
    tof_max_range_m: float = 2.0


def record_message(record: Record, stamp: Time, device_us: int, spec: SensorSpec
                   ) -> Imu | Range | SyncEvent:
    """Imu (accelerations [m/s²] with covariance, orientation and rates unknown), Range [m]
    (NaN when the sensor flags the reading) or SyncEvent of one record."""
    if record.kind == "IMU":
        msg = Imu()
        a = [v * STANDARD_GRAVITY * 1e-3 for v in record.values]
        msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z = a
        variance = (spec.accel_noise_mg * STANDARD_GRAVITY * 1e-3) ** 2
        msg.linear_acceleration_covariance = [variance, 0.0, 0.0, 0.0, variance, 0.0,
                                              0.0, 0.0, variance]
        msg.orientation_covariance[0] = -1.0
        msg.angular_velocity_covariance[0] = -1.0
    elif record.kind == "TOF":
        range_mm, status = record.values
        msg = Range(radiation_type=Range.INFRARED, field_of_view=spec.tof_field_of_view_rad,
                    min_range=spec.tof_min_range_m, max_range=spec.tof_max_range_m,
                    range=range_mm * 1e-3 if status == 0 else math.nan,
                    variance=(spec.tof_noise_mm * 1e-3) ** 2)
    else:
        msg = SyncEvent(kind=EVENT_KINDS[(record.kind, int(record.values[0] != 0))],
                        source="arduino", device_time_us=device_us, sequence=record.seq)
    msg.header.stamp, msg.header.frame_id = stamp, spec.frame_id
    return msg
