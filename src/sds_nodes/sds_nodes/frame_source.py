"""ROS 2 node publishing the frames of a video file, live camera or image folder."""

from __future__ import annotations

import queue
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import RCLError
from rclpy.time import Time
from sds_camera.camera_imu import CameraImuError, imu_samples, read_camera_imu
from sds_camera.frame_source import (
    Frame,
    FrameSourceError,
    Region,
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
from sds_ros.image_msg import image_to_msg
from sds_ros.imu_msg import imu_message
from sds_ros.qos import wait_for_acks
from sensor_msgs.msg import Image, Imu
from std_msgs.msg import Header

from sds_msgs.msg import CameraModel, SyncEvent

BEHIND_REPORT_S = 0.5
"""A file played in real time this far behind its frames' times is said on the console [s]."""
PARAMETER_CHOICES = {"channel": ("bgr", "red", "green", "blue", "gray"),
                     "pacing": ("realtime", "flood"), "stamp": ("clock", "media")}
"""The values a string parameter may take: a literal, which the launcher reads without
importing this module (`graph_file.check_plugins`), so that a wrong one fails before any
node starts; `channel`'s are the frame source's `CHANNELS`."""
IMU_HISTORY = 2000
"""Camera IMU messages kept for late subscribers (about 3 s of a GoPro's 600 per second)."""
EXIT_SOURCE_ERROR = 2
PARAMETERS = {"source": "", "fps": 0.0, "roi": [0, 0, 0, 0], "channel": "bgr",
              "pacing": "realtime", "rate": 1.0, "stamp": "clock", "frame_id": "camera_optical",
              "camera_model": "", "wait_for_subscribers": 1, "ack_consumers": 1,
              "max_in_flight": 2, "led_roi": [0, 0, 0, 0], "repeat": 1, "linger_s": 3.0,
              "follow": False, "stamp_offset_s": 0.0}
"""The node's parameters and defaults (config/params/frame_source.yaml documents each)."""


class _EndOfStream:
    """Marker put in the frame queue after the last frame; carries the error if any."""

    def __init__(self, error: FrameSourceError | None = None) -> None:
        self.error = error


class FrameSourceNode(HostedNode):
    """Publish frames as sensor_msgs/Image, paced in real time or as fast as consumers ack."""

    def __init__(self, node_name: str = "frame_source", **node_kwargs) -> None:
        super().__init__(node_name, **node_kwargs)
        self.published = 0
        self.behind_s = 0.0   # the furthest a file played in real time fell behind [s]
        values = self.declare_parameter_table(PARAMETERS)
        self._stop = threading.Event()
        self._queue: queue.Queue[Frame | _EndOfStream] = queue.Queue(maxsize=3)
        try:
            p = self._checked(values)
            self._source = open_source(p["source"], fps=p["fps"])
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
        self._decode_thread = threading.Thread(target=self._read_frames, name="decode", daemon=True)
        self._publish_thread = threading.Thread(
            target=self._publish_frames, name="publish", daemon=True
        )
        self._decode_thread.start()
        self._publish_thread.start()

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

    def _repeated_frames(self):
        """The source's frames, played `repeat` times (0: forever) with increasing index and
        time: one continuous stream (long runs from a short file)."""
        repeat, played, index, offset_ns, period_ns = int(self._p["repeat"]), 0, 0, 0, 0
        # The LED's corner lies outside the region: with an LED, whole frames are decoded.
        selection = (None, "bgr") if self._led is not None else (self._region, self._p["channel"])
        while True:
            last_ns = 0
            for frame in self._source.frames(*selection):
                yield Frame(index, offset_ns + frame.time_ns, frame.image)
                period_ns = frame.time_ns - last_ns if frame.time_ns > last_ns else period_ns
                last_ns, index = frame.time_ns, index + 1
            played += 1
            if (repeat and played >= repeat) or self._stop.is_set() or index == 0:
                return
            offset_ns += last_ns + period_ns
            self._source.close()
            self._source = open_source(self._p["source"], fps=self._p["fps"])

    def _read_frames(self) -> None:
        """Decode thread: select region and channel, hand frames to the publish thread."""
        end = _EndOfStream()
        try:
            for frame in self._repeated_frames():
                if self._led is not None:
                    switch = self._led.update(frame.index, frame.image)
                    if switch is not None:
                        self._led_switches[frame.index] = switch.on
                    image = select(frame.image, self._region, self._p["channel"])
                else:
                    image = frame.image
                if not self._put(Frame(frame.index, frame.time_ns, image)):
                    return
        except FrameSourceError as error:
            end = _EndOfStream(error)
        finally:
            self._source.close()
        self._put(end)

    def _put(self, item: Frame | _EndOfStream) -> bool:
        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def _wait_for_subscribers(self) -> bool:
        wanted = self._p["wait_for_subscribers"]
        last_log = 0.0
        while self._image_pub.get_subscription_count() < wanted and not self._stop.is_set():
            if time.monotonic() - last_log > 5.0:
                topic = self._image_pub.topic_name
                self.get_logger().info(f"waiting for {wanted} subscriber(s) on {topic}")
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

    def _publish_frames(self) -> None:
        """Publish thread: pace, stamp and publish frames until the stream ends."""
        p = self._p
        flow_control = p["pacing"] == "flood" and p["ack_consumers"] > 0
        if not self._source.is_live and not self._wait_for_subscribers():
            return
        origin = self._origin()
        if origin is None:
            return
        origin_ns, start = origin
        self._origin_pub.publish(Header(stamp=Time(nanoseconds=origin_ns).to_msg(),
                                        frame_id=p["frame_id"]))
        while not self._stop.is_set():
            try:
                item = self._queue.get(timeout=0.1)
            except queue.Empty:
                continue
            if isinstance(item, _EndOfStream):
                self._finish(item.error, flow_control)
                return
            if p["pacing"] == "realtime" and not self._source.is_live:
                delay = start + item.time_ns * 1e-9 / p["rate"] - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                elif -delay > BEHIND_REPORT_S:
                    self.behind_s = max(self.behind_s, -delay)
                    self.get_logger().warning(
                        f"playing {-delay:.1f} s behind real time (decoding and the graph need "
                        "more CPU than there is): frames come late, none is skipped",
                        throttle_duration_sec=10.0)
            stamp_ns = origin_ns + item.time_ns
            if flow_control:
                self._credit.wait(p["max_in_flight"] - 1)
                self._credit.register(stamp_ns)
            stamp = Time(nanoseconds=stamp_ns).to_msg()
            if not self._publish(image_to_msg(item.image, stamp, p["frame_id"])):
                return
            self.published += 1
            self._publish_imu_until(item.time_ns * 1e-9, origin_ns)
            led_on = self._led_switches.pop(item.index, None)
            if led_on is not None:
                led_stamp = Time(nanoseconds=stamp_ns + self._led_delay_ns).to_msg()
                self._sync_pub.publish(SyncEvent(
                    header=Header(stamp=led_stamp, frame_id=p["frame_id"]), source=p["frame_id"],
                    kind=SyncEvent.KIND_LED_ON if led_on else SyncEvent.KIND_LED_OFF))

    def _publish(self, msg: Image) -> bool:
        """Publish unless the node is stopping; False once the graph shuts down."""
        if self._stop.is_set():
            return False
        try:
            self._image_pub.publish(msg)
        except RCLError:
            if self.context.ok():
                raise
            return False
        return True

    def _finish(self, error: FrameSourceError | None, flow_control: bool) -> None:
        if flow_control:
            self._credit.wait(0)
        if self._stop.is_set():
            return
        wait_for_acks(self._image_pub, 5.0, self._stop)
        wait_for_acks(self._imu_pub, 5.0, self._stop)
        if error is not None:
            self._fail(f"{error}; the {self.published} frames published before stay valid")
            return
        behind = f", up to {self.behind_s:.1f} s behind real time" if self.behind_s else ""
        self.get_logger().info(f"end of {self._p['source']}: published {self.published} "
                               f"frames{behind}")
        # The consumers' last outputs: the tracker publishes the frames its Hampel window held
        # back once the stream has been idle for 1 s, the chain behind it follows.
        self._stop.wait(self._p["linger_s"])
        self.finished.set()

    def close(self) -> None:
        """Stop the decode and publish threads and wait for them."""
        self._stop.set()
        if hasattr(self, "_credit"):
            self._credit.release()
        for name in ("_decode_thread", "_publish_thread"):
            thread = getattr(self, name, None)
            if thread is not None:
                thread.join(timeout=2.0)


def main(args: list[str] | None = None) -> None:
    """Run the node alone in this process."""
    from sds_ros.node_host import run_nodes

    raise SystemExit(run_nodes([(FrameSourceNode, "frame_source", True)], args))
