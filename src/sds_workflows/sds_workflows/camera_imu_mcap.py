"""A camera's own IMU samples (GoPro GPMF, sidecar CSV) as /camera/imu messages in an MCAP."""

from __future__ import annotations

from pathlib import Path

from rclpy.serialization import serialize_message
from sds_camera.camera_imu import CameraImu, imu_samples
from sds_model.errors import InputError
from sds_model.staging import staged_file
from sds_record.mcap_files import McapRecorder
from sds_ros.imu_msg import imu_messages

from sds_workflows.run_tables import CAMERA_IMU_TOPIC


def write_imu_mcap(imu: CameraImu, output: Path, origin_ns: int, overwrite: bool = False,
                   frame_id: str = "camera_optical") -> int:
    """The camera IMU's samples as /camera/imu messages in a new MCAP (which appears only when
    complete); how many (those that would be stamped before 0 are left out: a ROS stamp is
    not negative). InputError when none is left."""
    if output.exists() and not overwrite:
        raise InputError(f"{output} exists (not replaced: another name, or --overwrite)")
    count = 0
    with staged_file(output) as staging:
        recorder = McapRecorder(staging)
        try:
            recorder.add_topic(CAMERA_IMU_TOPIC, "sensor_msgs/msg/Imu")
            for stamp_ns, msg in imu_messages(imu_samples(imu), origin_ns, frame_id):
                recorder.write(CAMERA_IMU_TOPIC, serialize_message(msg), stamp_ns, stamp_ns)
                count += 1
            if count == 0:
                raise InputError(f"none of the {len(imu_samples(imu))} IMU samples has a stamp "
                                 "of 0 or more: give the first frame's time (--start-s)")
        finally:
            recorder.close()
    return count
