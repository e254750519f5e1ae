"""ROS 2 node: the running graph in Rerun, live (spawned or connected viewer) or saved to .rrd."""

from __future__ import annotations

import threading

import rerun as rr
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.subscription import MessageInfo
from sds_model.rig import RigError, load_rig
from sds_ros.hosted_node import HostedNode
from sds_ros.shedding import LiveShedding, report_on_console, waited_s
from sds_viz.messages import log_message
from sds_viz.scene import RerunScene
from sensor_msgs.msg import Image, Imu, PointCloud2, Range

from sds_msgs.msg import (
    CameraModel,
    LaserLineProfile,
    LaserSpotArray,
    SloshingEstimate,
    SurfaceFit,
)

EXIT_CONFIG_ERROR = 2
SUBSCRIPTIONS = (("image", Image, "sensor_msgs/msg/Image"),
                 ("spots", LaserSpotArray, "sds_msgs/msg/LaserSpotArray"),
                 ("line", LaserLineProfile, "sds_msgs/msg/LaserLineProfile"),
                 ("points", PointCloud2, "sensor_msgs/msg/PointCloud2"),
                 ("line_points", PointCloud2, "sensor_msgs/msg/PointCloud2"),
                 ("surface_fit", SurfaceFit, "sds_msgs/msg/SurfaceFit"),
                 ("sloshing", SloshingEstimate, "sds_msgs/msg/SloshingEstimate"),
                 ("imu", Imu, "sensor_msgs/msg/Imu"),
                 ("tof", Range, "sensor_msgs/msg/Range"))
"""Relative topic, message class and type name of everything the viewer shows."""
SIDE_IMAGES = "lateral_image"
"""The side camera's frames (config/graphs/lateral.yaml), thinned on their own."""
LIVE_TOPICS = {"spots": "spots_live", "points": "points_live"}
"""With `live`, the spots and points as measured (before the Hampel filter, at once) instead."""


PARAMETERS = {"rig": "", "output": "", "connect": "", "spawn": False, "image_scale": 0.25,
              "image_every": 1, "lateral_image_every": 4, "live": False,
              "live_max_lag_s": 0.1}
"""The node's parameters and defaults (config/params/viewer.yaml documents each)."""


class ViewerNode(HostedNode):
    """Subscribe best-effort (never slowing the graph) and log every message to Rerun."""

    def __init__(self, node_name: str = "viewer", **node_kwargs) -> None:
        super().__init__(node_name, **node_kwargs)
        p = self.declare_parameter_table(PARAMETERS)
        try:
            rig = load_rig(p["rig"]) if p["rig"] else None
        except (RigError, OSError) as error:
            self.get_logger().error(f"cannot load the rig: {error}")
            self.exit_code = EXIT_CONFIG_ERROR
            self.finished.set()
            return
        self._stream = rr.RecordingStream("sds")
        if p["output"]:
            self._stream.save(p["output"])
        elif p["connect"]:
            self._stream.connect_grpc(p["connect"])
        elif p["spawn"]:
            self._stream.spawn()
        else:
            self.get_logger().warning("no output, connect or spawn: nothing will be shown")
        self._scene = RerunScene(self._stream, rig, float(p["image_scale"]))
        self._every = {"image": max(1, int(p["image_every"])),
                       SIDE_IMAGES: max(1, int(p["lateral_image_every"]))}
        self._images = {"image": 0, SIDE_IMAGES: 0}
        # Live, a late image costs the CPU its measurements need and shows the past.
        self._shedding = LiveShedding("viewer images", float(p["live_max_lag_s"])) \
            if p["live"] else None
        self._lock = threading.Lock()
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.create_subscription(CameraModel, "camera_model",
                                 self._logger_for("sds_msgs/msg/CameraModel"), latched)
        for topic, msg_type, type_name in (*SUBSCRIPTIONS,
                                           (SIDE_IMAGES, Image, "sensor_msgs/msg/Image")):
            stream = topic
            if p["live"]:
                topic = LIVE_TOPICS.get(topic, topic)
            self.create_subscription(msg_type, topic, self._logger_for(type_name, stream),
                                     qos_profile_sensor_data)
        if self._shedding is not None:
            report_on_console(self, self._shedding)
        where = p["output"] or p["connect"] or ("a spawned viewer" if p["spawn"] else "nowhere")
        self.get_logger().info(f"showing the graph in Rerun: {where}")

    def _logger_for(self, type_name: str, stream: str = ""):
        def log(msg, info: MessageInfo) -> None:
            if type_name == "sensor_msgs/msg/Image":
                self._images[stream] += 1
                if (self._images[stream] - 1) % self._every[stream]:
                    return
                if self._shedding is not None and not self._shedding.keep(waited_s(info)):
                    return
            with self._lock:
                log_message(self._scene, type_name, msg)
        return log

    def close(self) -> None:
        """Write out what is buffered (the .rrd is complete after this)."""
        if hasattr(self, "_stream"):
            self._stream.flush()
            self._stream.disconnect()


def main(args: list[str] | None = None) -> None:
    """Run the node alone in this process."""
    from sds_ros.node_host import run_nodes

    raise SystemExit(run_nodes([(ViewerNode, "viewer", False)], args))
