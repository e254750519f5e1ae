"""ROS 2 node publishing the frames of a video file, live camera or image folder, and a
video file's own compressed packets.

A file whose stream is H.264 or H.265 is read as packets: each is published as it is
(foxglove_msgs/CompressedVideo on `video`, for the recorder), then decoded for the measuring
chain (sensor_msgs/Image on `image`). Played in real time, a decoder that falls behind the
camera sheds: first the frames no other frame refers to (a stream's non-reference B-frames),
then, far behind, the packets up to the next keyframe; both are counted and said on the
console. The packets themselves are published whatever the CPU, so the recording holds every
frame and `sds process --mcap` measures them all."""

from __future__ import annotations

import queue
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import RCLError
from rclpy.time import Time
from sds_camera.camera_imu import CameraImuError, imu_samples, read_camera_imu
from sds_camera.compressed_video import (
    LivePackets,
    PacketDecoder,
    VideoFilePackets,
    VideoPacket,
    packet_format,
)
from sds_camera.frame_source import (
    Frame,
    FrameSource,
    FrameSourceError,
    Region,
    VideoFileSource,
    open_source,
    select,
)
from sds_camera.led import LedDetector
from sds_model.camera import CameraModel as CameraModelBase
from sds_model.camera import load_camera
from sds_model.camera.files import read_yaml
from sds_model.camera.rolling_shutter import RollingShutter, rolling_shutter
from sds_model.errors import InputError
from sds_ros.ack_credit import AckCredit
from sds_ros.hosted_node import HostedNode
from sds_ros.image_msg import image_to_msg, packet_msg
from sds_ros.imu_msg import imu_message
from sds_ros.qos import unacknowledged, wait_for_acks
from sds_ros.real_time import RealTimePace
from sensor_msgs.msg import CompressedImage, Image, Imu
from std_msgs.msg import Header

from foxglove_msgs.msg import CompressedVideo
from sds_msgs.msg import CameraModel, SyncEvent

PARAMETER_CHOICES = {"channel": ("bgr", "red", "green", "blue", "gray"),
                     "pacing": ("realtime", "flood"), "stamp": ("clock", "media"),
                     "input_format": ("", "h264", "mjpeg")}
"""The values a string parameter may take: a literal, which the launcher reads without
importing this module (`graph_file.check_plugins`), so that a wrong one fails before any
node starts; `channel`'s are the frame source's `CHANNELS`."""
DECODE_BACKLOG = 15
"""Packets waiting for the decoder (half a second at 30 fps): played in real time, a packet
that finds this many waiting is shed, with every packet up to the next keyframe."""
SKIP_BACKLOG = 5
"""Packets waiting for the decoder at which, played in real time, it leaves out the frames no
other frame refers to until none waits (a stream's non-reference B-frames: frames spread
over the run, not the gap up to the next keyframe that DECODE_BACKLOG sheds)."""
VIDEO_HISTORY = 150
"""The packet publisher's history (5 s at 30 fps): what a reliable reader that falls behind
for a while (the recorder writing a chunk) still gets. Packets are small (a few 100 kB)."""
IMU_HISTORY = 2000
"""Camera IMU messages kept for late subscribers (about 3 s of a GoPro's 600 per second)."""
EXIT_SOURCE_ERROR = 2
PARAMETERS = {"source": "", "fps": 0.0, "roi": [0, 0, 0, 0], "channel": "bgr",
              "pacing": "realtime", "rate": 1.0, "stamp": "clock", "frame_id": "camera_optical",
              "camera_model": "", "wait_for_subscribers": 1, "ack_consumers": 1,
              "max_in_flight": 2, "led_roi": [0, 0, 0, 0], "repeat": 1, "linger_s": 3.0,
              "follow": False, "stamp_offset_s": 0.0, "video": True,
              "packet_ack_consumers": 0, "wait_for_packet_subscribers": 0, "input_format": "",
              "low_delay": False, "realtime_acks": False}
"""The node's parameters and defaults (config/params/frame_source.yaml documents each)."""


T = TypeVar("T", Frame, VideoPacket)


class _EndOfStream:
    """Marker put in the frame queue after the last frame; carries the error if any."""

    def __init__(self, error: FrameSourceError | None = None) -> None:
        self.error = error


class FrameSourceNode(HostedNode):
    """Publish frames as sensor_msgs/Image, paced in real time or as fast as consumers ack."""

    def __init__(self, node_name: str = "frame_source", **node_kwargs) -> None:
        super().__init__(node_name, **node_kwargs)
        self.published = 0
        self.packets_published = 0
        self.shed = 0         # packets published but not decoded (shed)
        self.skipped_non_reference = False   # the decoder left out frames to catch up
        self._said_end = False
        values = self.declare_parameter_table(PARAMETERS)
        self._pace = RealTimePace(values["rate"], self.get_logger().warning,
                                  "reading and the graph need more CPU than there is: frames "
                                  "come late, none is skipped")
        self._stop = threading.Event()
        self._queue: queue.Queue[Frame | _EndOfStream] = queue.Queue(maxsize=3)
        self._decode_queue: queue.Queue[VideoPacket | _EndOfStream] = queue.Queue(
            maxsize=DECODE_BACKLOG)
        self._clock_started = threading.Event()
        self._origin_ns = 0
        self._packets: VideoFilePackets | LivePackets | None = None
        self._source: FrameSource
        try:
            p = self._checked(values)
            if p["input_format"]:
                live = LivePackets(p["source"], p["input_format"], fps=p["fps"])
                self._source, self._packets = live, live
            else:
                self._source = open_source(p["source"], fps=p["fps"])
            if p["video"] and isinstance(self._source, VideoFileSource) \
                    and packet_format(self._source.codec):
                self._packets = VideoFilePackets(p["source"])
            self._region = self._region_from(p["roi"])
            self._camera = self._camera_from(p["camera_model"])
            self._shutter = rolling_shutter(read_yaml(p["camera_model"])) \
                if p["camera_model"] else RollingShutter()
        except (FrameSourceError, OSError, ValueError) as error:
            self._fail(str(error))
            return
        depth = max(5, p["max_in_flight"] + 1)
        latched = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        reliable = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)
        self._image_pub = self.create_publisher(Image, "image", reliable)
        if self._packets is not None:
            # A stream's packets on `video`; Motion JPEG's (each a JPEG) on `image/compressed`.
            jpeg = self._packets.format == "jpeg"
            self._video_pub = self.create_publisher(
                CompressedImage if jpeg else CompressedVideo, "image/compressed" if jpeg
                else "video", QoSProfile(depth=VIDEO_HISTORY,
                                         reliability=ReliabilityPolicy.RELIABLE))
            self._packet_credit = AckCredit(p["packet_ack_consumers"],
                                            self.resolve_topic_name("packet_ack"),
                                            self.get_logger().warning)
            self.create_subscription(Header, "packet_ack", self._packet_credit.on_ack, reliable)
        self._model_pub = self.create_publisher(CameraModel, "camera_model", latched)
        # Kept for late subscribers (the bridge, a recorder): the blink comes at the start.
        self._sync_pub = self.create_publisher(SyncEvent, "sync", QoSProfile(
            depth=10, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL))
        roi = [int(v) for v in p["led_roi"]]
        self._led = LedDetector((roi[0], roi[1], roi[2], roi[3])) \
            if len(roi) == 4 and roi[2] > 0 else None
        # Under a rolling shutter the LED's rows are exposed after the frame's first row.
        self._led_delay_ns = round(1e9 * float(self._shutter.row_time_s(
            roi[1] + roi[3] / 2, self._source.height))) if self._led is not None else 0
        self._led_switches: dict[int, bool] = {}
        # Kept for a late subscriber (a recorder that matches after the first frames): the
        # samples of the first seconds come in a burst with the first frame.
        self._imu_pub = self.create_publisher(Imu, "imu", QoSProfile(
            depth=IMU_HISTORY, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self._imu_samples = self._camera_imu_samples(p["source"])
        self._credit = AckCredit(p["ack_consumers"], self.resolve_topic_name("frame_ack"),
                                 self.get_logger().warning)
        self.create_subscription(Header, "frame_ack", self._credit.on_ack, reliable)
        # The stamp of the first frame, for a second camera that plays beside this one.
        self._origin_pub = self.create_publisher(Header, "origin", latched)
        self._leader_origin_ns: int | None = None
        self._leader_seen = threading.Event()
        if p["follow"] and not self._source.is_live:
            self._leader_sub = self.create_subscription(Header, "leader_origin",
                                                        self._on_leader_origin, latched)
        self._publish_camera_model(p)
        readers: list[Callable[[], None]] = [self._read_frames] if self._packets is None \
            else [self._read_packets, self._decode_packets]
        self._threads = [threading.Thread(target=target, name=target.__name__, daemon=True)
                         for target in (*readers, self._publish_frames)]
        for thread in self._threads:
            thread.start()

    def _camera_imu_samples(self, source: str) -> deque[tuple[float, str, np.ndarray]]:
        """The source's own IMU samples (GPMF track or sidecar CSV), each published once the
        frame at or after its time is (first play only); one log line either way."""
        if self._source.is_live:
            return deque()
        try:
            imu = read_camera_imu(source)
        except (CameraImuError, OSError) as error:
            self.get_logger().warning(f"camera IMU of {source} not read: {error}")
            return deque()
        if imu is None:
            self.get_logger().info(f"{source} has no camera IMU (no GPMF track, no sidecar)")
            return deque()
        self.get_logger().info(f"camera IMU from {imu.source}: {len(imu.accel_time_s)} "
                               f"accelerometer and {len(imu.gyro_time_s)} gyroscope samples")
        return deque(imu_samples(imu))

    def _publish_imu_until(self, time_s: float, origin_ns: int) -> None:
        """Publish the camera IMU's samples up to `time_s` on the video's clock (those before
        the first frame or after the last are left out: the stream is the frames' span)."""
        while self._imu_samples and self._imu_samples[0][0] <= time_s:
            sample_s, sensor, value = self._imu_samples.popleft()
            if sample_s >= 0:
                _, msg = imu_message(sample_s, sensor, value, origin_ns, self._p["frame_id"])
                self._imu_pub.publish(msg)

    def _checked(self, p: dict[str, Any]) -> dict[str, Any]:
        """The parameters, once their values are known to be usable."""
        for name, allowed in PARAMETER_CHOICES.items():
            if p[name] not in allowed:
                raise InputError(f"parameter {name}={p[name]!r} is not one of {allowed}")
        if p["rate"] <= 0 or p["max_in_flight"] < 1 or p["linger_s"] < 0:
            raise InputError("parameters rate and max_in_flight must be positive, linger_s "
                             "not negative")
        if not p["source"]:
            raise InputError("parameter source is empty: name a video file, folder or camera")
        self._p = p
        return p

    def _region_from(self, roi: list[int]) -> Region:
        width, height = self._source.width, self._source.height
        if len(roi) != 4:
            raise FrameSourceError(f"roi must be [x, y, width, height], got {list(roi)}")
        region = Region.full(width, height) if roi[2] == 0 else Region(*map(int, roi))
        region.check_inside(width, height)
        return region

    def _camera_from(self, path: str) -> CameraModelBase | None:
        """The camera file's model (None without one); it must match the source's frame size."""
        if not path:
            return None
        camera = load_camera(path)
        size = (self._source.width, self._source.height)
        if (camera.width_px, camera.height_px) != size:
            raise InputError(f"camera model {path} is for {camera.width_px}x{camera.height_px} px "
                             f"frames, the source gives {size[0]}x{size[1]}")
        return camera

    def _publish_camera_model(self, p: dict) -> None:
        msg = CameraModel()
        msg.header.frame_id = p["frame_id"]
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.full_width, msg.full_height = self._source.width, self._source.height
        if self._camera is not None:
            path = Path(p["camera_model"])
            msg.model_path = str(path.resolve())
            msg.model_yaml = path.read_text()
            msg.model_type = self._camera.model_name
        msg.roi.x_offset, msg.roi.y_offset = self._region.x, self._region.y
        msg.roi.width, msg.roi.height = self._region.width, self._region.height
        msg.channel = p["channel"]
        self._model_pub.publish(msg)

    def _fail(self, reason: str) -> None:
        self.get_logger().error(reason)
        self.exit_code = EXIT_SOURCE_ERROR
        self.finished.set()

    def _repeated(self, play: Callable[[], Iterator[T]], reopen: Callable[[], None]
                  ) -> Iterator[T]:
        """The items (frames or packets) of `play()`, played `repeat` times (0: forever) with
        increasing index and time, `reopen()` between plays: one continuous stream (long runs
        from a short file). The next play starts a frame period (the mean of this one's)
        after the last frame."""
        repeat, played, index, offset_ns = int(self._p["repeat"]), 0, 0, 0
        while True:
            last_ns, count = 0, 0
            for item in play():
                yield replace(item, index=index, time_ns=offset_ns + item.time_ns) \
                    if isinstance(item, Frame) else replace(
                        item, index=index, time_ns=offset_ns + item.time_ns,
                        due_ns=offset_ns + item.due_ns)
                last_ns, count, index = max(last_ns, item.time_ns), count + 1, index + 1
            played += 1
            if (repeat and played >= repeat) or self._stop.is_set() or index == 0:
                return
            offset_ns += last_ns + (last_ns // (count - 1) if count > 1 else 0)
            reopen()

    def _selection(self) -> tuple[Region | None, str]:
        """What is decoded: the LED's corner lies outside the region, so with an LED whole
        frames (in BGR, cut to the region after the LED is read)."""
        return (None, "bgr") if self._led is not None else (self._region, self._p["channel"])

    def _reopen_source(self) -> None:
        self._source.close()
        self._source = open_source(self._p["source"], fps=self._p["fps"])

    def _hand_on(self, frame: Frame) -> bool:
        """Read the LED of a decoded frame, cut it to the region, queue it for publishing;
        False once stopping."""
        if self._led is None:
            return self._put(self._queue, frame)
        switch = self._led.update(frame.index, frame.image)
        if switch is not None:
            self._led_switches[frame.index] = switch.on
        image = select(frame.image, self._region, self._p["channel"])
        return self._put(self._queue, Frame(frame.index, frame.time_ns, image))

    def _read_frames(self) -> None:
        """Decode thread (a source without packets): frames to the publish thread."""
        end = _EndOfStream()
        try:
            for frame in self._repeated(lambda: self._source.frames(*self._selection()),
                                        self._reopen_source):
                if not self._hand_on(frame):
                    return
        except FrameSourceError as error:
            end = _EndOfStream(error)
        finally:
            self._source.close()
        self._put(self._queue, end)

    def _read_packets(self) -> None:
        """Packet thread: pace and publish every packet, hand it to the decode thread; played
        in real time, a packet the decoder has no room for is shed, with the packets up to
        the next keyframe (decoding can only start again there)."""
        assert self._packets is not None
        p, end = self._p, _EndOfStream()
        if not self._start_clock():
            return
        flow_control = p["pacing"] == "flood" and p["packet_ack_consumers"] > 0
        shedding = False
        try:
            for packet in self._repeated(lambda: self._packets.packets(),  # type: ignore[union-attr]
                                         lambda: None):
                if p["pacing"] == "realtime":
                    self._wait_until(packet.due_ns)
                stamp_ns = self._origin_ns + packet.time_ns
                if flow_control:
                    self._packet_credit.wait(p["max_in_flight"] - 1)
                    self._packet_credit.register(stamp_ns)
                if not self._publish(self._video_pub, packet_msg(
                        packet.data, Time(nanoseconds=stamp_ns).to_msg(), p["frame_id"],
                        self._packets.format)):
                    return
                self.packets_published += 1
                self._publish_imu_until(packet.time_ns * 1e-9, self._origin_ns)
                shedding = shedding and not packet.keyframe
                if p["pacing"] == "flood":
                    if not self._put(self._decode_queue, packet):
                        return
                    continue
                try:
                    if not shedding:
                        self._decode_queue.put_nowait(packet)
                        continue
                except queue.Full:
                    shedding = True
                self.shed += 1
                self.get_logger().warning(
                    f"decoding falls behind the camera: {self.shed} frame(s) shed so far (not "
                    "measured live; their packets are published, so the recording holds them)",
                    throttle_duration_sec=10.0)
        except FrameSourceError as error:
            end = _EndOfStream(error)
        finally:
            self._packets.close()
        self._put(self._decode_queue, end)

    def _decode_packets(self) -> None:
        """Decode thread (a source with packets): the packets' frames to the publish thread."""
        decoder = PacketDecoder(self._packets.format, *self._selection(),  # type: ignore[union-attr]
                                low_delay=self._p["low_delay"])
        realtime = self._p["pacing"] == "realtime"
        while not self._stop.is_set():
            try:
                item = self._decode_queue.get(timeout=0.1)
            except queue.Empty:
                continue
            if realtime:
                self._skip_when_behind(decoder)
            try:
                frames = decoder.flush() if isinstance(item, _EndOfStream) \
                    else decoder.decode(item)
            except FrameSourceError as error:
                self._put(self._queue, _EndOfStream(error))
                return
            for frame in frames:
                if not self._hand_on(frame):
                    return
            if isinstance(item, _EndOfStream):
                self._put(self._queue, item)
                return

    def _skip_when_behind(self, decoder: PacketDecoder) -> None:
        """Leave out the non-reference frames from SKIP_BACKLOG packets waiting until none
        waits; say so when it starts (at most once a minute: a machine short of CPU starts
        it every few seconds, and the camera's last line counts the frames left out)."""
        backlog = self._decode_queue.qsize()
        if backlog >= SKIP_BACKLOG and not decoder.skipping_non_reference:
            decoder.skipping_non_reference = True
            self.skipped_non_reference = True
            self.get_logger().warning(
                f"decoding falls behind the camera ({backlog} packets waiting): the frames no "
                "other frame refers to are not decoded until it catches up (not measured live; "
                "their packets are published, so the recording holds them)",
                throttle_duration_sec=60.0)
        elif backlog == 0 and decoder.skipping_non_reference:
            decoder.skipping_non_reference = False

    def _put(self, destination: queue.Queue, item: Any) -> bool:
        """Queue an item, waiting for room; False once stopping."""
        while not self._stop.is_set():
            try:
                destination.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def _wait_for_subscribers(self) -> bool:
        """Wait for the image (and packet) subscribers and the camera model's readers; False
        once stopping."""
        wanted = [(self._image_pub, self._p["wait_for_subscribers"])]
        if self._packets is not None:
            wanted.append((self._video_pub, self._p["wait_for_packet_subscribers"]))
        last_log = 0.0
        while any(publisher.get_subscription_count() < count for publisher, count in wanted) \
                and not self._stop.is_set():
            if time.monotonic() - last_log > 5.0:
                self.get_logger().info("waiting for " + " and ".join(
                    f"{count} subscriber(s) on {publisher.topic_name}"
                    for publisher, count in wanted if count))
                last_log = time.monotonic()
            time.sleep(0.02)
        # The model first, where its readers have matched (not a guarantee: a reader that
        # matches later gets it after the first frames; the tracker keeps those frames).
        if not wait_for_acks(self._model_pub, 5.0, self._stop):
            self.get_logger().warning("camera_model not acknowledged by every subscriber in "
                                      "5 s; publishing frames anyway")
        return not self._stop.is_set()

    def _on_leader_origin(self, msg: Header) -> None:
        if self._leader_origin_ns is None:
            self._leader_origin_ns = Time.from_msg(msg.stamp).nanoseconds
            self._leader_seen.set()

    def _origin(self) -> tuple[int, float] | None:
        """The stamp [ns] of media time 0 and the monotonic time [s] it is played at; a
        follower (a file) takes its leader's first frame's, moved by `stamp_offset_s` (its
        frame 0 on the leader's clock), and plays from when that arrives, later by the offset
        if it is positive (frames before the leader's first are not rushed out in a burst
        that a subscriber's queue would drop: they come that much late); None once
        stopping."""
        p = self._p
        offset_ns = round(p["stamp_offset_s"] * 1e9)
        if p["follow"] and not self._source.is_live:
            leader = self.resolve_topic_name("leader_origin")
            self.get_logger().info(f"waiting for the leading camera's first frame ({leader})")
            while not self._leader_seen.wait(0.1):
                if self._stop.is_set():
                    return None
            assert self._leader_origin_ns is not None
            return (self._leader_origin_ns + offset_ns,
                    time.monotonic() + max(p["stamp_offset_s"], 0.0) / p["rate"])
        origin_ns = self.get_clock().now().nanoseconds if p["stamp"] == "clock" else 0
        return origin_ns + offset_ns, time.monotonic()

    def _start_clock(self) -> bool:
        """Wait for the subscribers (a file), fix the origin and publish it; False once
        stopping. The thread that paces does it: the packet thread, else the publish thread."""
        if not self._source.is_live and not self._wait_for_subscribers():
            return False
        origin = self._origin()
        if origin is None:
            return False
        self._origin_ns, start_s = origin
        self._pace.start(start_s)
        self._origin_pub.publish(Header(stamp=Time(nanoseconds=self._origin_ns).to_msg(),
                                        frame_id=self._p["frame_id"]))
        self._clock_started.set()
        return True

    def _wait_until(self, time_ns: int) -> None:
        """Sleep until media time `time_ns` is due in real time (a file; a live source's
        frames come when they come); say so when it is long past."""
        if not self._source.is_live:
            self._pace.wait_until(time_ns * 1e-9)

    def _publish_frames(self) -> None:
        """Publish thread: pace (without packets), stamp and publish frames until the stream
        ends."""
        p = self._p
        flow_control = p["ack_consumers"] > 0 and (
            p["pacing"] == "flood" or (p["realtime_acks"] and not self._source.is_live))
        if self._packets is None:
            if not self._start_clock():
                return
        else:
            while not self._clock_started.wait(0.1):
                if self._stop.is_set():
                    return
        origin_ns = self._origin_ns
        while not self._stop.is_set():
            try:
                item = self._queue.get(timeout=0.1)
            except queue.Empty:
                continue
            if isinstance(item, _EndOfStream):
                self._finish(item.error, flow_control)
                return
            if p["pacing"] == "realtime" and self._packets is None:
                self._wait_until(item.time_ns)
            stamp_ns = origin_ns + item.time_ns
            if flow_control:
                self._credit.wait(p["max_in_flight"] - 1)
                self._credit.register(stamp_ns)
            stamp = Time(nanoseconds=stamp_ns).to_msg()
            if not self._publish(self._image_pub, image_to_msg(item.image, stamp, p["frame_id"])):
                return
            self.published += 1
            if self._packets is None:   # else the packets' thread publishes them
                self._publish_imu_until(item.time_ns * 1e-9, origin_ns)
            led_on = self._led_switches.pop(item.index, None)
            if led_on is not None:
                led_stamp = Time(nanoseconds=stamp_ns + self._led_delay_ns).to_msg()
                self._sync_pub.publish(SyncEvent(
                    header=Header(stamp=led_stamp, frame_id=p["frame_id"]), source=p["frame_id"],
                    kind=SyncEvent.KIND_LED_ON if led_on else SyncEvent.KIND_LED_OFF))

    def _publish(self, publisher: Publisher, msg: Image | CompressedVideo | CompressedImage
                 ) -> bool:
        """Publish unless the node is stopping; False once the graph shuts down."""
        if self._stop.is_set():
            return False
        try:
            publisher.publish(msg)
        except RCLError:
            if self.context.ok():
                raise
            return False
        return True

    def _finish(self, error: FrameSourceError | None, flow_control: bool) -> None:
        if flow_control:
            self._credit.wait(0)
        if self._packets is not None:
            self._packet_credit.wait(0)
        if self._stop.is_set():
            return
        unacknowledged([self._image_pub, self._imu_pub,
                        *([self._video_pub] if self._packets is not None else [])],
                       5.0, self._stop)
        if error is not None:
            self._fail(f"{error}; the {self.published} frames published before stay valid")
            return
        self.get_logger().info(f"end of {self._p['source']}: {self._published_line()}")
        self._said_end = True
        # The consumers' last outputs: the tracker publishes the frames its Hampel window held
        # back once the stream has been idle for 1 s, the chain behind it follows.
        self._stop.wait(self._p["linger_s"])
        self.finished.set()

    def _published_line(self) -> str:
        """What was published: packets, frames, frames shed, how far behind real time."""
        behind = self._pace.behind_clause()
        if self._packets is None:
            return f"published {self.published} frames{behind}"
        # Shed: the packets not decoded, the frames a decoder could not make without them and
        # those it left out to catch up.
        unmeasured = self.packets_published - self.published
        shed = (f" ({unmeasured} more shed while decoding fell behind: in the recording, not "
                "measured live)") if self.shed or self.skipped_non_reference else ""
        return (f"published {self.published} frames{shed} and the {self.packets_published} "
                f"video packets they came in{behind}")

    def close(self) -> None:
        """Stop the reading, decoding and publish threads and wait for them."""
        self._stop.set()
        for name in ("_credit", "_packet_credit"):
            if hasattr(self, name):
                getattr(self, name).release()
        for thread in getattr(self, "_threads", []):
            thread.join(timeout=2.0)
        if not hasattr(self, "_threads") or self._said_end:
            return
        # Stopped before its end: the console says what was published, which the recording
        # is held against (the node host then waits for the last packets to be acknowledged:
        # `node_host.wait_for_readers`).
        self.get_logger().info(f"stopped: {self._published_line()}")


def main(args: list[str] | None = None) -> None:
    """Run the node alone in this process."""
    from sds_ros.node_host import run_nodes

    raise SystemExit(run_nodes([(FrameSourceNode, "frame_source", True)], args))
