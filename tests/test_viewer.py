"""Rerun: `sds view` on a recording and the viewer node in a graph write .rrd files that
Rerun's own CLI (`rerun rrd print`) reads back with the expected entities."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from rclpy.serialization import serialize_message
from ros_helpers import LATCHED, RELIABLE, Probe, SdsGraphRun
from rrd_helpers import rrd_entities
from sds_model.rig import load_rig, rig_document
from sds_recon.reconstruction import SurfacePoints
from sds_record.mcap_files import McapRecorder
from sds_ros.image_msg import image_to_msg
from sds_ros.point_cloud import points_to_cloud
from sds_viz.messages import log_message
from sensor_msgs.msg import Imu
from std_msgs.msg import String

from sds_msgs.msg import CameraModel, LaserSpot, LaserSpotArray, SurfaceFit

SDS = str(Path(sys.executable).with_name("sds"))
EXPECTED = {"/camera/image": "Image", "/camera/image/spots": "Points2D",
            "/camera/image/beam_paths": "LineStrips2D", "/world/container": "LineStrips3D",
            "/world/beams": "LineStrips3D", "/world/points": "Points3D",
            "/world/fitted_plane": "Mesh3D", "/series/height/0": "Scalars",
            "/series/modal/lateral_1_cos": "Scalars", "/series/plane/tilt_x_deg": "Scalars"}


def frame_messages(rig, index: int) -> list[tuple[str, str, object]]:
    """One frame's image, spots, cloud and fit as the graph publishes them."""
    stamp = Time(sec=100, nanosec=index * 33_000_000)
    image = np.zeros((540, 960), np.uint8)
    spots = LaserSpotArray(frame_index=index)
    spots.header.stamp = stamp
    spots.spots = [LaserSpot(laser_id=d.laser_id, x_px=1900.0 + d.laser_id, y_px=1080.0,
                             sigma_px=0.05) for d in rig.diodes]
    count = len(rig.diodes)
    points = SurfacePoints(np.array([d.laser_id for d in rig.diodes]),
                           np.column_stack([[d.emitter_mm[0] for d in rig.diodes],
                                            [d.emitter_mm[1] for d in rig.diodes],
                                            np.full(count, 0.1 * index)]),
                           np.full(count, 0.02), np.zeros(count))
    fit = SurfaceFit(frame_index=index, p00_mm=0.1 * index, p10=0.01, p01=0.0,
                     tilt_x_rad=-0.01, tilt_y_rad=0.0, rmse_mm=0.02,
                     mode_names=["mean", "lateral_1_cos"], modal_amplitudes_mm=[0.0, 1.0])
    fit.header.stamp = stamp
    return [("/camera/image", "sensor_msgs/msg/Image", image_to_msg(image, stamp, "camera")),
            ("/tracker/spots", "sds_msgs/msg/LaserSpotArray", spots),
            ("/recon/points", "sensor_msgs/msg/PointCloud2",
             points_to_cloud(spots.header, points)),
            ("/recon/surface_fit", "sds_msgs/msg/SurfaceFit", fit)]


def test_sds_view_turns_a_recording_into_rerun_entities(repo: Path, tmp_path: Path) -> None:
    rig = load_rig(repo / "config" / "rigs" / "stelium.yaml")
    recording = McapRecorder(tmp_path / "run.mcap")
    model = CameraModel(full_width=3840, full_height=2160)
    model.roi.x_offset, model.roi.y_offset = 1365, 519
    recording.add_topic("/camera/camera_model", "sds_msgs/msg/CameraModel", latched=True)
    recording.write("/camera/camera_model", serialize_message(model), 0, 0)
    recording.add_topic("/recon/rig", "std_msgs/msg/String", latched=True)   # as the graph's
    recording.write("/recon/rig", serialize_message(String(data=rig_document(rig))), 0, 0)
    for index in range(3):
        for topic, type_name, msg in frame_messages(rig, index):
            recording.add_topic(topic, type_name)
            recording.write(topic, serialize_message(msg), index + 1, index + 1)
    for topic, msg in imu_messages():
        recording.add_topic(topic, "sensor_msgs/msg/Imu")
        recording.write(topic, serialize_message(msg), 5, 5)
    recording.close()
    done = subprocess.run([SDS, "view", str(tmp_path / "run.mcap"), "--out",
                           str(tmp_path / "run.rrd")], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert "16 messages shown" in done.stdout
    entities = rrd_entities(tmp_path / "run.rrd")
    for entity, archetype in EXPECTED.items():
        assert archetype in entities.get(entity, set()), (entity, sorted(entities))
    imu_series = {e for e in entities if e.startswith("/series/imu/")}
    assert imu_series == {f"/series/imu/arduino/a{axis}_m_s2" for axis in "xyz"} | {
        f"/series/imu/camera_optical/{quantity}" for quantity in (
            "ax_m_s2", "ay_m_s2", "az_m_s2", "gx_rad_s", "gy_rad_s", "gz_rad_s")}


def imu_messages() -> list[tuple[str, Imu]]:
    """The Arduino's accelerometer (rig axes) and the camera's accelerometer and gyroscope
    (optical axes, one sensor per message), as the graph publishes them."""
    arduino = Imu()
    arduino.header.frame_id = "arduino"
    arduino.linear_acceleration.z = 9.8
    arduino.angular_velocity_covariance[0] = arduino.orientation_covariance[0] = -1.0
    accel, gyro = Imu(), Imu()
    accel.header.frame_id = gyro.header.frame_id = "camera_optical"
    accel.linear_acceleration.y = -9.86
    accel.angular_velocity_covariance[0] = accel.orientation_covariance[0] = -1.0
    gyro.angular_velocity.x = 0.1
    gyro.linear_acceleration_covariance[0] = gyro.orientation_covariance[0] = -1.0
    return [("/arduino/imu", arduino), ("/camera/imu", accel), ("/camera/imu", gyro)]


class LoggedImu:
    """A scene that keeps what it is asked to log of the IMU."""

    def __init__(self) -> None:
        self.samples: list[tuple[str, str, tuple[float, float, float]]] = []

    def set_time(self, time_s: float) -> None:
        pass

    def log_imu(self, frame_id: str, sensor: str, values: tuple[float, float, float]) -> None:
        self.samples.append((frame_id, sensor, values))


def test_each_imu_source_and_sensor_is_a_series_of_its_own() -> None:
    scene = LoggedImu()
    for _, msg in imu_messages():
        assert log_message(scene, "sensor_msgs/msg/Imu", msg)
    assert scene.samples == [("arduino", "accel", (0.0, 0.0, 9.8)),
                             ("camera_optical", "accel", (0.0, -9.86, 0.0)),
                             ("camera_optical", "gyro", (0.1, 0.0, 0.0))]


@pytest.mark.ros
@pytest.mark.parametrize("live", [False, True])
def test_viewer_node_saves_what_the_graph_publishes(repo: Path, tmp_path: Path,
                                                    live: bool) -> None:
    rig_file = repo / "config" / "rigs" / "stelium.yaml"
    rig = load_rig(rig_file)
    output = tmp_path / "live.rrd"
    graph = SdsGraphRun("view.yaml", "--set", f"viewer.output={output}",
                        "--set", f"viewer.rig={rig_file}", "--set", f"viewer.live={live}")
    # With viewer.live the spots and points come from the live previews instead.
    renamed = {"/tracker/spots": "/tracker/spots_live", "/recon/points": "/recon/points_live"}
    probe = Probe("viewer_probe")
    try:
        publishers = {topic: probe.node.create_publisher(
                          type(msg), renamed.get(topic, topic) if live else topic, RELIABLE)
                      for topic, _, msg in frame_messages(rig, 0)}
        model_pub = probe.node.create_publisher(CameraModel, "/camera/camera_model", LATCHED)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and not all(
                p.get_subscription_count() for p in (*publishers.values(), model_pub)):
            time.sleep(0.05)
        model_pub.publish(CameraModel(full_width=3840, full_height=2160))
        for index in range(5):
            for topic, _, msg in frame_messages(rig, index):
                publishers[topic].publish(msg)
            time.sleep(0.1)
        time.sleep(1.0)
    finally:
        probe.close()
        graph.stop()
    entities = rrd_entities(output)
    for entity, archetype in EXPECTED.items():
        assert archetype in entities.get(entity, set()), (entity, sorted(entities), graph.output())
