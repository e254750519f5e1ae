"""ROS 2 node that receives images, acknowledges them, and reports rate and latency."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from sds_ros.hosted_node import HostedNode
from sds_ros.image_msg import msg_to_image
from sensor_msgs.msg import Image
from std_msgs.msg import Header

PARAMETERS = {"ack": True, "summary_path": "", "report_period_s": 2.0}
"""The node's parameters and defaults (config/params/frame_monitor.yaml documents each)."""


class FrameMonitorNode(HostedNode):
    """Count received frames, ack each one on frame_ack, and write a JSON summary at the end."""

    def __init__(self, node_name: str = "frame_monitor", **node_kwargs) -> None:
        super().__init__(node_name, **node_kwargs)
        p = self.declare_parameter_table(PARAMETERS)
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self._ack = p["ack"]
        self._ack_pub = self.create_publisher(Header, "frame_ack", reliable)
        self.create_subscription(Image, "image", self._on_image, reliable)
        self._summary_path = p["summary_path"]
        self._stamps_ns: list[int] = []
        self._latencies_ms: list[float] = []
        self._arrivals_s: list[float] = []
        self._shape: tuple[int, ...] = ()
        self._encoding = ""
        self.create_timer(p["report_period_s"], self._report)

    def _on_image(self, msg: Image) -> None:
        now_ns = self.get_clock().now().nanoseconds
        stamp_ns = Time.from_msg(msg.header.stamp).nanoseconds
        self._shape = msg_to_image(msg).shape
        self._encoding = msg.encoding
        if self._ack:
            ack = Header(stamp=msg.header.stamp, frame_id=self.get_name())
            self._ack_pub.publish(ack)
        self._stamps_ns.append(stamp_ns)
        self._latencies_ms.append((now_ns - stamp_ns) * 1e-6)
        self._arrivals_s.append(time.monotonic())

    def summary(self) -> dict:
        """Frames received, receive rate [fps], stamp-to-receipt latency [ms], order errors."""
        count = len(self._stamps_ns)
        span = self._arrivals_s[-1] - self._arrivals_s[0] if count > 1 else 0.0
        latency = np.array(self._latencies_ms) if count else np.full(1, np.nan)
        return {
            "frames": count,
            "receive_fps": (count - 1) / span if span > 0 else float("nan"),
            "latency_ms_median": float(np.median(latency)),
            "latency_ms_p95": float(np.percentile(latency, 95)),
            "out_of_order": int(np.sum(np.diff(self._stamps_ns) <= 0)) if count > 1 else 0,
            "shape": list(self._shape),
            "encoding": self._encoding,
        }

    def _report(self) -> None:
        if self._stamps_ns:
            s = self.summary()
            self.get_logger().info(
                f"{s['frames']} frames, {s['receive_fps']:.1f} fps, "
                f"latency median {s['latency_ms_median']:.1f} ms"
            )

    def close(self) -> None:
        """Write the summary file if one was asked for."""
        if self._summary_path:
            Path(self._summary_path).write_text(json.dumps(self.summary(), indent=2))


def main(args: list[str] | None = None) -> None:
    """Run the node alone in this process."""
    from sds_ros.node_host import run_nodes

    raise SystemExit(run_nodes([(FrameMonitorNode, "frame_monitor", False)], args))
