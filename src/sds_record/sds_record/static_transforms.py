"""The static transform a recording carries on /tf_static: the rig's world frame → the camera.

Foxglove (and any tf-aware reader of the MCAP) then draws the surface cloud (`world`) and the
camera (`camera_optical`, the frame source's frame) together. REP-103: metres, the child's
pose in the parent frame (translation = the camera centre, rotation = camera to world). The
PyPI wheels have no tf2_msgs classes, so the message is serialized with rosbags' standard
Kilted definition of tf2_msgs/msg/TFMessage.
"""

from __future__ import annotations

from scipy.spatial.transform import Rotation
from sds_model.rig import Rig

from sds_record.schemas import standard_typestore

TF_STATIC_TOPIC = "/tf_static"
TF_MESSAGE_TYPE = "tf2_msgs/msg/TFMessage"
WORLD_FRAME = "world"
CAMERA_FRAME = "camera_optical"


def camera_transform_cdr(rig: Rig, stamp_ns: int, world_frame: str = WORLD_FRAME,
                         camera_frame: str = CAMERA_FRAME) -> bytes:
    """A tf2_msgs/TFMessage (CDR) with the transform world → camera of the rig [m]."""
    store = standard_typestore()
    types = store.types
    camera_to_world = rig.world_to_camera.rotation.T
    x, y, z = (float(v) / 1000.0 for v in rig.camera_position_mm)
    qx, qy, qz, qw = (float(v) for v in Rotation.from_matrix(camera_to_world).as_quat())
    stamp = types["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9,
                                                 nanosec=stamp_ns % 10**9)
    transform = types["geometry_msgs/msg/TransformStamped"](
        header=types["std_msgs/msg/Header"](stamp=stamp, frame_id=world_frame),
        child_frame_id=camera_frame,
        transform=types["geometry_msgs/msg/Transform"](
            translation=types["geometry_msgs/msg/Vector3"](x=x, y=y, z=z),
            rotation=types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw)))
    message = types[TF_MESSAGE_TYPE](transforms=[transform])
    return bytes(store.serialize_cdr(message, TF_MESSAGE_TYPE))
