"""ROS 2 node: play an MCAP recording into the graph, with /clock, at a rate or as fast as
acked; a camera's recorded packets decoded into frames for the measuring chain."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from pathlib import Path

from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from rclpy.time import Time
from rosgraph_msgs.msg import Clock
from sds_camera.compressed_video import PacketDecoder, VideoPacket
from sds_camera.frame_source import Frame, FrameSourceError, Region
from sds_model.errors import InputError
from sds_record.mcap_files import (
    RecordedMessage,
    decoded_messages,
    header_stamp_ns,
    read_messages,
    recorded_topics,
)
from sds_ros.ack_credit import AckCredit
from sds_ros.hosted_node import HostedNode
from sds_ros.image_msg import PACKET_TYPES, image_to_msg, packet_fields
from sds_ros.qos import stream_qos, unacknowledged
from sds_ros.real_time import RealTimePace
from sensor_msgs.msg import CompressedImage, Image
from std_msgs.msg import Header

from foxglove_msgs.msg import CompressedVideo
from sds_nodes.recorder import message_class

EXIT_INPUT_ERROR = 2
PARAMETER_CHOICES = {"pacing": ("recorded", "flood")}
"""The values a string parameter may take (a literal the launcher checks before starting)."""
DEPTH = 100
"""Messages kept per played topic, for readers that lag (3.3 s at 30 fps)."""
IMAGE_TYPE = "sensor_msgs/msg/Image"
MODEL_TYPE = "sds_msgs/msg/CameraModel"


@dataclass
class _Decoding:
    """A recorded packet topic played as frames: where they go, how they are cut."""

    target: str
    decoder: PacketDecoder | None = None   # made at the first packet, from its format
    region: Region | None = None
    channel: str = "bgr"
    frame_id: str = ""


def parse_remaps(items: list[str]) -> dict[str, str]:
    """'from:=to' pairs as a dictionary."""
    remaps = {}
    for item in (i for i in items if i):
        source, separator, target = item.partition(":=")
        if not separator or not source or not target:
            raise InputError(f"remap {item!r}: give FROM:=TO")
        remaps[source] = target
    return remaps


PARAMETERS = {"input": "", "topics": [""], "remap": [""], "rate": 1.0, "pacing": "recorded",
              "start_s": 0.0, "stop_s": 0.0, "clock": True, "wait_for_subscribers": 1,
              "ack_topic_for": "", "ack_consumers": 1, "max_in_flight": 2, "linger_s": 2.0,
              "decode": [""]}
"""The node's parameters and defaults (config/params/player.yaml documents each)."""


class PlayerNode(HostedNode):
    """Publish a recording's messages as they were (serialized), in log-time order.

    `pacing: recorded` keeps the recorded intervals divided by `rate`; `pacing: flood` goes as
    fast as the consumers of `ack_topic_for` acknowledge (the frame source's frame_ack
    protocol), so nothing is dropped. /clock follows the recording's log time. A `decode`
    pair FROM:=TO plays the camera packets recorded on FROM also as frames on TO (decoded, cut
    to the region and channel of the recording's camera model of their frame_id), unless the
    recording has frames on TO itself.
    """

    def __init__(self, node_name: str = "player", **node_kwargs) -> None:
        super().__init__(node_name, **node_kwargs)
        self.published = 0
        self.decoded = 0     # frames decoded from recorded packets and published
        self._p = self.declare_parameter_table(PARAMETERS)
        self._pace = RealTimePace(self._p["rate"], self.get_logger().warning,
                                  "decoding the camera's packets and the graph need more CPU "
                                  "than there is: messages come late, none is skipped")
        self._stop = threading.Event()
        self._credit = AckCredit(self._p["ack_consumers"], self.resolve_topic_name("frame_ack"),
                                 self.get_logger().warning)
        self._outputs: dict[str, Publisher] = {}
        self._decodings: dict[str, _Decoding] = {}
        try:
            self._remaps = parse_remaps(self._p["remap"])
            self._check_parameters()
            self._create_publishers()
            self._create_decodings()
        except (ValueError, OSError, ImportError, AttributeError) as error:
            self._fail(str(error))
            return
        self._clock_pub = self.create_publisher(Clock, "/clock", 10)
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(Header, "frame_ack", self._credit.on_ack, reliable)
        self._thread = threading.Thread(target=self._play, name="play", daemon=True)
        self._thread.start()

    def _check_parameters(self) -> None:
        p = self._p
        if not p["input"] or not Path(p["input"]).is_file():
            raise InputError(f"parameter input={p['input']!r}: no such recording")
        if p["pacing"] not in PARAMETER_CHOICES["pacing"]:
            raise InputError(f"parameter pacing={p['pacing']!r} is not one of "
                             f"{PARAMETER_CHOICES['pacing']}")
        if p["rate"] <= 0:
            raise InputError("parameter rate must be positive")

    def _fail(self, reason: str) -> None:
        self.get_logger().error(reason)
        self.exit_code = EXIT_INPUT_ERROR
        self.finished.set()

    def _create_publishers(self) -> None:
        """One publisher per played topic before anything is sent (so that subscribers, a
        recorder's discovery, can find them all first). Frames are volatile, as the frame
        source's; every other topic is transient-local: it feeds the chain's transient-local
        readers (`sds_ros.qos`) and volatile ones alike, also from recordings made when the
        topic was volatile."""
        selected = {t for t in self._p["topics"] if t}
        for topic, (type_name, _latched) in recorded_topics(self._p["input"]).items():
            if selected and topic not in selected:
                continue
            qos = QoSProfile(depth=DEPTH, reliability=ReliabilityPolicy.RELIABLE) \
                if type_name == IMAGE_TYPE else stream_qos(DEPTH)
            self._outputs[topic] = self.create_publisher(
                message_class(type_name), self._remaps.get(topic, topic), qos)

    def _create_decodings(self) -> None:
        """An Image publisher for each `decode` pair whose packets are in the recording and
        whose frames are not."""
        recorded = recorded_topics(self._p["input"])
        for source, target in parse_remaps(self._p["decode"]).items():
            if recorded.get(source, ("",))[0] not in PACKET_TYPES or target in recorded:
                continue
            self._decodings[source] = _Decoding(target)
            self._outputs[target] = self.create_publisher(
                Image, self._remaps.get(target, target),
                QoSProfile(depth=DEPTH, reliability=ReliabilityPolicy.RELIABLE))
            self.get_logger().info(f"the packets of {source} are decoded and played as frames "
                                   f"on {target}")
        if self._decodings:
            self._models = {msg.header.frame_id: msg for _, msg in decoded_messages(
                self._p["input"], types=[MODEL_TYPE])}

    def _decoded_frames(self, message: RecordedMessage) -> list[Frame]:
        """The frames a recorded packet completes, stamped [ns] as their packets."""
        decoding = self._decodings[message.topic]
        frame_id, stamp_ns, packet_format, data = packet_fields(deserialize_message(
            message.data, CompressedImage if message.type_name == "sensor_msgs/msg/CompressedImage"
            else CompressedVideo))
        if decoding.decoder is None:
            decoding.frame_id = frame_id
            model = self._models.get(frame_id)
            if model is not None and model.roi.width > 0:
                decoding.region = Region(int(model.roi.x_offset), int(model.roi.y_offset),
                                         int(model.roi.width), int(model.roi.height))
                decoding.channel = model.channel or "bgr"
            decoding.decoder = PacketDecoder(packet_format, decoding.region, decoding.channel)
        return decoding.decoder.decode(VideoPacket(0, stamp_ns, False, data))

    def _wait_for_subscribers(self) -> bool:
        """Wait until every played topic has `wait_for_subscribers` subscribers."""
        wanted = self._p["wait_for_subscribers"]
        while not self._stop.is_set() and any(
                publisher.get_subscription_count() < wanted
                for publisher in self._outputs.values()):
            time.sleep(0.02)
        return not self._stop.is_set()

    def _play(self) -> None:
        """Publish thread: every selected message between the start and stop offsets."""
        p = self._p
        topics = [t for t in p["topics"] if t] or None
        flow_topic = p["ack_topic_for"] if p["pacing"] == "flood" else ""
        first_ns = None
        started = False
        try:
            for message in read_messages(p["input"], topics):
                if self._stop.is_set():
                    return
                if first_ns is None:
                    first_ns = message.log_time_ns
                offset_s = (message.log_time_ns - first_ns) * 1e-9
                if offset_s < p["start_s"]:
                    continue
                if p["stop_s"] > 0 and offset_s > p["stop_s"]:
                    break
                publisher = self._outputs[message.topic]
                if not started:
                    if not self._wait_for_subscribers():
                        return
                    self._pace.start(time.monotonic() - offset_s / p["rate"])
                    started = True
                if p["pacing"] == "recorded":
                    self._pace.wait_until(offset_s)
                if message.topic == flow_topic:
                    self._credit.wait(p["max_in_flight"] - 1)
                    self._credit.register(header_stamp_ns(message.data))
                if p["clock"]:
                    self._clock_pub.publish(Clock(clock=Time(
                        nanoseconds=message.log_time_ns).to_msg()))
                publisher.publish(message.data)
                self.published += 1
                if message.topic in self._decodings:
                    self._play_frames(message.topic, self._decoded_frames(message), flow_topic)
            for topic, decoding in self._decodings.items():
                if decoding.decoder is not None:
                    self._play_frames(topic, decoding.decoder.flush(), flow_topic)
        except (OSError, ValueError, ImportError, AttributeError, FrameSourceError) as error:
            self._fail(f"cannot play {p['input']}: {error}")
            return
        if flow_topic:
            self._credit.drain(timeout_s=10.0)
        unacknowledged(list(self._outputs.values()), 5.0, self._stop)
        decoded = f" and {self.decoded} frames decoded from its packets" if self._decodings else ""
        self.get_logger().info(f"played {self.published} messages from {p['input']}{decoded}"
                               f"{self._pace.behind_clause()}")
        self._stop.wait(p["linger_s"])   # the consumers' last outputs (e.g. the Hampel window)
        self.finished.set()

    def _play_frames(self, source: str, frames: list[Frame], flow_topic: str) -> None:
        """Publish decoded frames (their time: the stamp [ns]) on the decoding's target."""
        decoding = self._decodings[source]
        for frame in frames:
            if decoding.target == flow_topic:
                self._credit.wait(self._p["max_in_flight"] - 1)
                self._credit.register(frame.time_ns)
            self._outputs[decoding.target].publish(image_to_msg(
                frame.image, Time(nanoseconds=frame.time_ns).to_msg(),
                decoding.frame_id))
            self.decoded += 1

    def close(self) -> None:
        """Stop publishing (the graph is shutting down) and wait for the publish thread."""
        self._stop.set()
        self._credit.release()
        thread = getattr(self, "_thread", None)
        if thread is not None:
            thread.join(timeout=2.0)


def main(args: list[str] | None = None) -> None:
    """Run the node alone in this process."""
    from sds_ros.node_host import run_nodes

    raise SystemExit(run_nodes([(PlayerNode, "player", True)], args))
