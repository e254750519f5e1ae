"""ROS 2 messages (rclpy's, or decoded from MCAP: the same fields) into the Rerun scene."""

from __future__ import annotations

import numpy as np
from sds_recon.reconstruction import LINE_LASER_ID
from sds_ros.image_msg import msg_to_image
from sds_ros.point_cloud import read_cloud, stamp_s
from sds_ros.static_tf import LATERAL_FRAME

from sds_msgs.msg import LaserSpot
from sds_viz.scene import RerunScene


def log_message(scene: RerunScene, type_name: str, msg) -> bool:
    """Log one message by its type ('package/msg/Type'); False for a type the scene ignores."""
    if type_name == "sds_msgs/msg/CameraModel":
        if msg.header.frame_id == LATERAL_FRAME:   # the side camera's: no region, no beams
            return True
        scene.roi_offset = np.array([msg.roi.x_offset, msg.roi.y_offset], dtype=float)
        scene.roi_size = (int(msg.roi.width), int(msg.roi.height))
        scene.log_beam_paths()
        return True
    handler = HANDLERS.get(type_name)
    if handler is None:
        return False
    scene.set_time(stamp_s(msg))
    handler(scene, msg)
    return True


def _image(scene: RerunScene, msg) -> None:
    if msg.header.frame_id == LATERAL_FRAME:
        scene.log_side_image("lateral/image", msg_to_image(msg))
    else:
        scene.log_image(msg_to_image(msg), tuple(scene.roi_offset.astype(int)))


def _spots(scene: RerunScene, msg) -> None:
    ids = np.array([s.laser_id for s in msg.spots], dtype=int)
    pixels = np.array([[s.x_px, s.y_px] for s in msg.spots], dtype=float).reshape(-1, 2)
    lost = np.array([bool(s.flags & LaserSpot.FLAG_LOST) for s in msg.spots], dtype=bool)
    scene.log_spots(ids, pixels, lost | ~np.isfinite(pixels).all(axis=1))


def _line(scene: RerunScene, msg) -> None:
    scene.log_line(np.column_stack([np.asarray(msg.x_px, float), np.asarray(msg.y_px, float)]))


def _cloud(scene: RerunScene, msg) -> None:
    cloud = read_cloud(msg)
    if cloud is None:
        return
    ids, points = cloud.points.laser_ids, cloud.points.points_mm
    line = ids == LINE_LASER_ID
    if line.any():
        scene.log_line_points(points[line])
    if (~line).any():
        scene.log_points(ids[~line], points[~line])


def _fit(scene: RerunScene, msg) -> None:
    scene.log_surface_fit(msg.p00_mm, msg.p10, msg.p01, msg.tilt_x_rad, msg.tilt_y_rad,
                          msg.rmse_mm, list(msg.mode_names), list(msg.modal_amplitudes_mm))


def _estimate(scene: RerunScene, msg) -> None:
    scene.log_estimate(msg.mode, msg.method, msg.frequency_hz, msg.damping_ratio)


def _imu(scene: RerunScene, msg) -> None:
    """Each sensor the message carries (REP-145: covariance[0] −1 marks one it does not), in a
    series of its own per frame: the Arduino's (rig axes) and the camera's (optical axes) are
    different quantities."""
    source = msg.header.frame_id or "imu"
    if msg.linear_acceleration_covariance[0] != -1:
        a = msg.linear_acceleration
        scene.log_imu(source, "accel", (a.x, a.y, a.z))
    if msg.angular_velocity_covariance[0] != -1:
        g = msg.angular_velocity
        scene.log_imu(source, "gyro", (g.x, g.y, g.z))


def _tof(scene: RerunScene, msg) -> None:
    if np.isfinite(msg.range):
        scene.log_tof(msg.range * 1e3)


HANDLERS = {
    "sensor_msgs/msg/Image": _image,
    "sds_msgs/msg/LaserSpotArray": _spots,
    "sds_msgs/msg/LaserLineProfile": _line,
    "sensor_msgs/msg/PointCloud2": _cloud,
    "sds_msgs/msg/SurfaceFit": _fit,
    "sds_msgs/msg/SloshingEstimate": _estimate,
    "sensor_msgs/msg/Imu": _imu,
    "sensor_msgs/msg/Range": _tof,
}
"""What the scene shows, by message type."""
