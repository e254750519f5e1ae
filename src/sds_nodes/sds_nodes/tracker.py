"""ROS 2 node: images in, laser spots (Hampel-filtered) and the line profile out.

Each frame's spots are also published at once on `spots_live`, as measured and flagged
NOT_FILTERED, for a live view: the filtered ones on `spots` wait for the centred Hampel window
to close (hampel_window // 2 frames later)."""

from __future__ import annotations

from collections import deque

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import MessageInfo
from sds_model.rig import Rig, load_rig
from sds_ros.frame_gaps import FrameGaps
from sds_ros.hosted_node import HostedNode
from sds_ros.image_msg import msg_to_image
from sds_ros.point_cloud import stamp_s
from sds_ros.qos import live_qos, start_when_consumed, stream_qos
from sds_ros.shedding import LiveShedding, report_on_console, waited_s
from sds_tracker.spots import LOST
from sds_tracker.tracker import (
    TRACKING_PARAMETERS,
    FrameTracker,
    TrackedSpot,
    parse_seeds,
    tracker_config,
)
from sensor_msgs.msg import Image
from std_msgs.msg import Header

from sds_msgs.msg import CameraModel, LaserLineProfile, LaserSpot, LaserSpotArray

EXIT_CONFIG_ERROR = 2
IDLE_FLUSH_S = 1.0
"""With no frame for this long, the spots still held by the Hampel window are published."""
CHANNEL_INDEX = {"red": None, "bgr": 2}
WAITING_FRAMES = 30
"""Frames kept while the camera_model (region offset) has not arrived yet."""


def spots_msg(header: Header, frame: int, spots: list[TrackedSpot], rig: Rig
              ) -> LaserSpotArray:
    """One frame's spots as a LaserSpotArray, each with its row's time (the rig camera's
    rolling shutter)."""
    offsets = rig.camera_shutter.row_time_s([spot.y_px for spot in spots], rig.camera.height_px)
    return LaserSpotArray(header=header, frame_index=frame, spots=[
        LaserSpot(laser_id=spot.laser_id, x_px=spot.x_px, y_px=spot.y_px,
                  sigma_px=float(spot.sigma_px), x_raw_px=spot.x_raw_px, y_raw_px=spot.y_raw_px,
                  peak_intensity=float(spot.peak), flags=int(spot.flags),
                  t_offset_s=float(offset)) for spot, offset in zip(spots, offsets, strict=True)])


PARAMETERS = {"rig": "", "ack": True, **TRACKING_PARAMETERS, "lost_report_frames": 15,
              "wait_for_consumers": 0, "live_max_lag_s": 0.1, "image_depth": 2}
"""The node's parameters and defaults: the tracking ones from `sds_tracker.tracker` (shared with
`sds process`), and the node's own (config/params/tracker.yaml documents each)."""


class TrackerNode(HostedNode):
    """Track the rig's spots and line in every frame; frames must be the red channel or BGR."""

    def __init__(self, node_name: str = "tracker", **node_kwargs) -> None:
        super().__init__(node_name, **node_kwargs)
        self._p = self.declare_parameter_table(PARAMETERS)
        try:
            rig = load_rig(self._p["rig"])
            self._rig = rig
            values = {name: self._p[name] for name in TRACKING_PARAMETERS}
            self._tracker = FrameTracker(rig, tracker_config(values), parse_seeds(values["seeds"]))
        except (OSError, ValueError) as error:  # RigError is a ValueError
            self.get_logger().error(f"cannot start the tracker: {error}")
            self.exit_code = EXIT_CONFIG_ERROR
            self.finished.set()
            return
        self._ack = bool(self._p["ack"])
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._spots_pub = self.create_publisher(LaserSpotArray, "spots", stream_qos())
        self._live_pub = self.create_publisher(LaserSpotArray, "spots_live", live_qos())
        self._line_pub = self.create_publisher(LaserLineProfile, "line", stream_qos())
        self._ack_pub = self.create_publisher(Header, "frame_ack", reliable)
        self._offset: tuple[int, int] | None = None
        self._waiting: deque[tuple[Image, MessageInfo]] = deque(maxlen=WAITING_FRAMES)
        self._headers: deque[tuple[int, Header]] = deque(maxlen=64)
        self._frame = 0
        self._last_frame_time = self.get_clock().now()
        self._flushed = True
        self._lost_streak: dict[int, int] = {}
        self._gaps = FrameGaps()
        self._shedding = LiveShedding("spots_live", float(self._p["live_max_lag_s"]))
        report_on_console(self, self._shedding)
        self.create_timer(0.25, self._flush_if_idle)
        # No frame is taken before the spots have their consumers: none is lost to them.
        start_when_consumed(self, [(self._spots_pub, int(self._p["wait_for_consumers"]))],
                            lambda: self._subscribe_inputs(latched))

    def _subscribe_inputs(self, latched: QoSProfile) -> None:
        self.create_subscription(CameraModel, "camera_model", self._on_model, latched)
        # The newest frames only: a tracker behind its camera skips the older ones (counted
        # from the gaps in the stamps) instead of falling further behind. A flooding source
        # waits for each frame's ack, so it never has more frames waiting than this.
        self.create_subscription(Image, "image", self._on_image, QoSProfile(
            depth=int(self._p["image_depth"]), reliability=ReliabilityPolicy.RELIABLE))

    def _report_lost(self, frame: int, spots) -> None:
        """Say which lasers are not found: at the first frame, and after a long loss."""
        limit = int(self._p["lost_report_frames"])
        for spot in spots:
            streak = self._lost_streak.get(spot.laser_id, 0) + 1 if spot.flags & LOST else 0
            self._lost_streak[spot.laser_id] = streak
            if frame == 0 and streak:
                self.get_logger().warning(f"laser {spot.laser_id} not found on its image path "
                                          "in the first frame")
            elif streak == limit:
                self.get_logger().warning(f"laser {spot.laser_id} lost for {limit} frames "
                                          f"(since frame {frame - limit + 1})")

    def _on_model(self, msg: CameraModel) -> None:
        self._offset = (int(msg.roi.x_offset), int(msg.roi.y_offset))
        if msg.channel not in CHANNEL_INDEX:
            self.get_logger().error(f"frames carry channel {msg.channel!r}; the tracker needs "
                                    "'red' (mono8) or 'bgr'")
        while self._waiting:   # frames that arrived before the model, in order (acked)
            self._track(*self._waiting.popleft(), acknowledge=False)

    def _on_image(self, msg: Image, info: MessageInfo) -> None:
        if self._offset is None:
            # The latched camera_model can arrive after the first frames (a replay plays it
            # where the recorder logged it): keep them, and acknowledge them now, or a
            # flooding source would wait for these acks before it sends the model.
            if len(self._waiting) == self._waiting.maxlen:
                self.get_logger().warning("no camera_model: region offset unknown, oldest "
                                          "waiting frame dropped", throttle_duration_sec=5.0)
                self._waiting.popleft()
            self._waiting.append((msg, info))
            self._acknowledge(msg)
            return
        self._track(msg, info)

    def _track(self, msg: Image, info: MessageInfo, acknowledge: bool = True) -> None:
        """Track one frame (the camera model, and so the region's offset, is known)."""
        assert self._offset is not None   # _on_image keeps frames until the model comes
        image = msg_to_image(msg)
        red = image[..., 2] if image.ndim == 3 else image
        missing = self._gaps.missed(stamp_s(msg))
        if missing:   # frames keep the camera's numbers
            self._frame += missing
            self.get_logger().warning(
                f"{missing} frame(s) missing before frame {self._frame}, "
                f"{self._gaps.missed_in_all} in all (a gap in the frames' stamps: the camera "
                "or the tracker fell behind); their spots are not in the results",
                throttle_duration_sec=5.0)
        frame = self._frame
        self._frame += 1
        self._headers.append((frame, msg.header))
        ready, line = self._tracker.process(frame, red, self._offset)
        live = self._tracker.unfiltered(frame)
        if live and self._shedding.keep(waited_s(info)):
            self._live_pub.publish(spots_msg(msg.header, frame, live, self._rig))
        self._publish_spots(ready)
        self._line_pub.publish(LaserLineProfile(
            header=msg.header, frame_index=frame, x_px=line.x_px.tolist(),
            y_px=line.y_px.tolist(), sigma_px=line.sigma_px.astype(float).tolist(),
            peak_intensity=line.peak.astype(float).tolist(), flags=line.flags.tolist()))
        self._last_frame_time = self.get_clock().now()
        self._flushed = False
        if acknowledge:
            self._acknowledge(msg)

    def _acknowledge(self, msg: Image) -> None:
        if self._ack:
            self._ack_pub.publish(Header(stamp=msg.header.stamp, frame_id=self.get_name()))

    def _publish_spots(self, ready) -> None:
        headers = dict(self._headers)
        for frame, spots in ready:
            self._report_lost(frame, spots)
            self._spots_pub.publish(spots_msg(headers.get(frame, Header()), frame, spots,
                                              self._rig))

    def _flush_if_idle(self) -> None:
        idle = (self.get_clock().now() - self._last_frame_time).nanoseconds * 1e-9
        if not self._flushed and idle > IDLE_FLUSH_S:
            self._flush("stream idle")

    def _flush(self, why: str) -> None:
        """Publish the spots the Hampel window still holds (its last frames, filtered over the
        frames before them) and say so."""
        self._publish_spots(self._tracker.flush())
        self._flushed = True
        self.get_logger().info(f"{why}: published the last spots ({self._frame} frames "
                               "tracked)")

    def close(self) -> None:
        """Stopped before the stream went idle (Ctrl-C in a live run): the frames the Hampel
        window holds are published as at an idle stream's end, not lost; the node host then
        lets a reconstruction in this process take them (`messages_taken`)."""
        if not getattr(self, "_flushed", True):   # False once a frame was tracked
            self._flush("stopped")


def main(args: list[str] | None = None) -> None:
    """Run the node alone in this process."""
    from sds_ros.node_host import run_nodes

    raise SystemExit(run_nodes([(TrackerNode, "tracker", False)], args))

