"""ROS 2 node: record the graph's topics (all, or a chosen set) to an MCAP file."""

from __future__ import annotations

import importlib
from datetime import datetime
from pathlib import Path

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import MessageInfo
from rclpy.time import Time
from sds_record.mcap_files import McapRecorder, header_stamp_ns
from sds_record.schemas import SchemaError
from sds_ros.frame_gaps import PublisherGaps
from sds_ros.hosted_node import HostedNode
from std_msgs.msg import Header

EXIT_CONFIG_ERROR = 2
SKIPPED_TOPICS = ("/rosout", "/parameter_events")
IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage",
               "foxglove_msgs/msg/CompressedVideo")
SMALL_MESSAGE_DEPTH = 5000
"""Queue depth of the topics that are not images (small messages, high rates)."""


def message_class(type_name: str) -> type:
    """The Python message class of 'package/msg/Type'."""
    package, kind, name = type_name.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


PARAMETERS = {"output": "", "topics": [""], "exclude": [""], "compression": "zstd",
              "flush_period_s": 0.5, "discovery_period_s": 0.5, "queue_depth": 100,
              "ack_for": [""], "packet_ack_for": [""], "overwrite": False}
"""The node's parameters and defaults (config/params/recorder.yaml documents each)."""


def ack_topic(topic: str, kind: str) -> str:
    """The topic on which `topic`'s messages are acknowledged: `kind` (frame_ack or
    packet_ack) beside it, e.g. /camera/image -> /camera/frame_ack, where the frame source of
    /camera/image (remapped as in config/graphs/) waits for it."""
    return f"{topic.rsplit('/', 1)[0]}/{kind}"


class RecorderNode(HostedNode):
    """Subscribe (reliably, serialized) to every topic it discovers, or to `topics`; write MCAP.

    Messages of the `ack_for` topics are acknowledged once written on the frame_ack topic
    beside each (`ack_topic`: /camera/image on /camera/frame_ack), those of the
    `packet_ack_for` topics (the camera's packets) on the packet_ack beside each (a frame
    source that waits for acks then waits for the recorder too, so no frame or packet is
    dropped).
    Latched topics (all publishers transient-local, e.g. the camera model) are subscribed
    transient-local so their last message is recorded even if it was sent before the recorder
    started. The log time is the recorder's ROS clock at reception (simulated time with
    use_sim_time); the publish time is the DDS source timestamp.
    """

    def __init__(self, node_name: str = "recorder", **node_kwargs) -> None:
        super().__init__(node_name, **node_kwargs)
        p = self.declare_parameter_table(PARAMETERS)
        output = p["output"] or f"recordings/sds_{datetime.now():%Y%m%d_%H%M%S}.mcap"
        self._wanted = {t for t in p["topics"] if t}
        self._excluded = {t for t in p["exclude"] if t}
        self._depth = int(p["queue_depth"])
        self._ack_for = {t for t in p["ack_for"] if t}
        self._packet_ack_for = {t for t in p["packet_ack_for"] if t}
        try:
            self._recorder = McapRecorder(output, p["compression"],
                                          flush_period_s=p["flush_period_s"],
                                          overwrite=bool(p["overwrite"]))
        except (ValueError, OSError) as error:
            self.get_logger().error(f"cannot record to {output}: {error}")
            self.exit_code = EXIT_CONFIG_ERROR
            self.finished.set()
            return
        self._recorded: dict[str, object] = {}
        self._gaps: dict[str, PublisherGaps] = {}
        acks = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self._ack_pubs = {topic: self.create_publisher(Header, ack_topic(topic, kind), acks)
                          for kind, topics in (("frame_ack", self._ack_for),
                                               ("packet_ack", self._packet_ack_for))
                          for topic in topics}
        self._failed: set[str] = set()
        self.output = Path(output)
        self.get_logger().info(f"recording to {self.output}")
        self._discover()
        self.create_timer(float(p["discovery_period_s"]), self._discover)
        self.create_timer(0.1, self._recorder.flush_if_due)

    def _discover(self) -> None:
        """Subscribe to new topics that match the selection."""
        for topic, types in self.get_topic_names_and_types():
            if topic in self._recorded or topic in self._failed or topic in SKIPPED_TOPICS \
                    or topic in self._excluded or (self._wanted and topic not in self._wanted):
                continue
            type_name = types[0]
            qos = self._qos_for(topic, type_name)
            if qos is None:
                continue   # a subscriber's topic with no publisher yet: its QoS is unknown
            try:
                self._recorder.add_topic(topic, type_name,
                                         qos.durability == DurabilityPolicy.TRANSIENT_LOCAL)
                msg_type = message_class(type_name)
            except (SchemaError, ImportError, AttributeError, ValueError) as error:
                self.get_logger().error(f"cannot record {topic} ({type_name}): {error}")
                self._failed.add(topic)
                continue
            self._recorded[topic] = self.create_subscription(
                msg_type, topic, self._writer_for(topic), qos, raw=True)
            self.get_logger().info(f"recording {topic} ({type_name})")

    def _qos_for(self, topic: str, type_name: str) -> QoSProfile | None:
        """Reliable, keep-last `queue_depth` for images and SMALL_MESSAGE_DEPTH for the rest
        (a burst of small messages, e.g. the camera IMU's 600 per second, must not overflow
        the queue while a 4K frame is written); transient-local when every publisher is (a
        latched topic, a stream of `sds_ros.qos`); None while the topic has no publisher."""
        publishers = self.get_publishers_info_by_topic(topic)
        if not publishers:
            return None
        latched = all(
            p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in publishers)
        best_effort = any(p.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
                          for p in publishers)
        depth = self._depth if type_name in IMAGE_TYPES else max(self._depth,
                                                                 SMALL_MESSAGE_DEPTH)
        return QoSProfile(
            depth=depth, history=HistoryPolicy.KEEP_LAST,
            reliability=ReliabilityPolicy.BEST_EFFORT if best_effort
            else ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)

    def _writer_for(self, topic: str):
        acks = self._ack_pubs.get(topic)
        gaps = self._gaps.setdefault(topic, PublisherGaps())

        def write(data: bytes, info: MessageInfo) -> None:
            now_ns = self.get_clock().now().nanoseconds
            if gaps.missed(info):
                self.get_logger().warning(
                    f"{gaps.missed_in_all} message(s) of {topic} never reached the recorder "
                    "(it fell behind their publisher): they are not in the recording",
                    throttle_duration_sec=5.0)
            self._recorder.write(topic, data, now_ns, int(info["source_timestamp"]))
            if acks is not None:
                acks.publish(Header(stamp=Time(nanoseconds=header_stamp_ns(data)).to_msg()))
        return write

    def messages_taken(self) -> int | None:
        """Messages written so far: at a stop, the node host takes what was delivered before
        the file is finished (`node_host.drain`)."""
        return self._recorder.message_count if hasattr(self, "_recorder") else None

    def close(self) -> None:
        """Finish the file (summary section) when the graph stops; a file without a message
        is removed."""
        if hasattr(self, "_recorder"):
            lost = {topic: gaps.missed_in_all for topic, gaps in self._gaps.items()
                    if gaps.missed_in_all}
            early = {topic: gaps.before_first for topic, gaps in self._gaps.items()
                     if gaps.before_first}
            self._recorder.close(not_recorded={
                topic: lost.get(topic, 0) + early.get(topic, 0) for topic in {*lost, *early}})
            if self._recorder.message_count == 0:   # it would only block the retry
                self.output.unlink(missing_ok=True)
                self.get_logger().warning(f"no message came: {self.output} removed")
                return
            self.get_logger().info(f"wrote {self._recorder.message_count} messages to "
                                   f"{self.output}")
            if lost:
                self.get_logger().warning(
                    "never reached the recorder, so not in it: " + ", ".join(
                        f"{count} of {topic}" for topic, count in lost.items()))
            if early:
                self.get_logger().warning(
                    "published before the recorder subscribed, so not in it: " + ", ".join(
                        f"{count} of {topic}" for topic, count in early.items()))


def main(args: list[str] | None = None) -> None:
    """Run the node alone in this process."""
    from sds_ros.node_host import run_nodes

    raise SystemExit(run_nodes([(RecorderNode, "recorder", False)], args))
