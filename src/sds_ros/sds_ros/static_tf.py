"""The rig's static transforms (/tf_static, live and in recordings), REP-103: metres, each
child frame's pose in the world frame of the rig file.

world → camera_optical: the camera centre and its rotation (camera to world), the frame the
frame source stamps its images in. world → arduino: the Arduino's accelerometer, whose axes are
the rig's (results/imu.csv: ax along X, the excitation) and whose position on the rig is not
described (zero: a direction-only frame for its IMU messages).
"""

from __future__ import annotations

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Quaternion, Transform, TransformStamped, Vector3
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from scipy.spatial.transform import Rotation
from sds_model.rig import Rig
from std_msgs.msg import Header

from tf2_msgs.msg import TFMessage

TF_STATIC_TOPIC = "/tf_static"
WORLD_FRAME = "world"
CAMERA_FRAME = "camera_optical"
LATERAL_FRAME = "lateral_optical"
"""The side camera's optical frame (config/graphs/lateral.yaml): a recording tells its frames
and camera model from the top camera's by it."""
ARDUINO_FRAME = "arduino"


def static_tf_qos() -> QoSProfile:
    """tf2's static broadcaster's QoS: reliable, transient-local, keep-last 1, so that a
    listener that starts later still gets the transforms."""
    return QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def rig_transforms(rig: Rig, stamp: Time, world_frame: str = WORLD_FRAME) -> TFMessage:
    """The rig's static transforms: world → camera_optical, world → arduino [m]."""
    camera_to_world = rig.world_to_camera.rotation.T
    x, y, z = (float(v) / 1000.0 for v in rig.camera_position_mm)
    qx, qy, qz, qw = (float(v) for v in Rotation.from_matrix(camera_to_world).as_quat())
    camera = TransformStamped(
        header=Header(stamp=stamp, frame_id=world_frame), child_frame_id=CAMERA_FRAME,
        transform=Transform(translation=Vector3(x=x, y=y, z=z),
                            rotation=Quaternion(x=qx, y=qy, z=qz, w=qw)))
    arduino = TransformStamped(header=Header(stamp=stamp, frame_id=world_frame),
                               child_frame_id=ARDUINO_FRAME,
                               transform=Transform(rotation=Quaternion(w=1.0)))
    return TFMessage(transforms=[camera, arduino])
