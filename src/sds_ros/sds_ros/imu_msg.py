"""The camera's IMU samples as sensor_msgs/Imu messages, one sensor per message.

The accelerometer (about 200 Hz) and the gyroscope (about 400 Hz) are not sampled together,
so each message carries one of them and marks the other unknown (element 0 of its covariance
−1, as sensor_msgs/Imu asks); orientation is always unknown. SI units, the camera's optical
frame (`frame_id`), stamps = `origin_ns` + the sample's time on the video's clock.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np
from builtin_interfaces.msg import Time
from sensor_msgs.msg import Imu
from std_msgs.msg import Header

UNKNOWN = [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
"""A covariance that says "not measured" (sensor_msgs/Imu)."""


def imu_message(time_s: float, sensor: str, value: np.ndarray, origin_ns: int,
                frame_id: str) -> tuple[int, Imu]:
    """One sample as an Imu message and its stamp [ns]."""
    stamp_ns = origin_ns + round(time_s * 1e9)
    msg = Imu(header=Header(stamp=Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
                            frame_id=frame_id))
    msg.orientation_covariance = list(UNKNOWN)
    x, y, z = (float(v) for v in value)
    if sensor == "accel":
        msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z = x, y, z
        msg.angular_velocity_covariance = list(UNKNOWN)
    else:
        msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = x, y, z
        msg.linear_acceleration_covariance = list(UNKNOWN)
    return stamp_ns, msg


def imu_messages(samples: Iterable[tuple[float, str, np.ndarray]], origin_ns: int,
                 frame_id: str) -> Iterator[tuple[int, Imu]]:
    """Every sample (time [s], "accel" or "gyro", value; `camera_imu.imu_samples`) whose stamp
    is not negative, in order."""
    for time_s, sensor, value in samples:
        if origin_ns + time_s * 1e9 >= 0:
            yield imu_message(time_s, sensor, value, origin_ns, frame_id)
