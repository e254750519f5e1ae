"""The one per-frame pipeline: camera frames in, tracked spots, surface points and fits out.

`FramePipeline` runs the graph's own per-frame code in one process (FrameTracker, then
frame_points for the Hampel-filtered spots, fitted at the frame's time by InstantFits, and
reconstruct_line for the line, Eqs. 9–12) with the tracker's and reconstruction's parameters
of config/graphs/drop.yaml, so that `sds process`, the benches, the tests and a notebook get
what the graph's nodes compute. The frames come from `video_frames` (a video or an image
folder) or `mcap_frames` (a recording's images).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from sds_camera.compressed_video import PacketDecoder, VideoPacket
from sds_camera.frame_source import (
    FrameSource,
    FrameSourceError,
    Region,
    VideoFileSource,
    open_source,
    read_ahead,
)
from sds_model.paths import CONFIG
from sds_model.rig import Rig
from sds_recon.instant import InstantFits
from sds_recon.reconstruction import (
    SurfaceFits,
    SurfacePoints,
    frame_points,
    reconstruct_line,
)
from sds_record.mcap_files import decoded_messages, recorded_topics
from sds_ros.graph_file import node_parameters
from sds_ros.image_msg import PACKET_TYPES, msg_to_image, packet_fields
from sds_ros.point_cloud import stamp_ns
from sds_ros.static_tf import LATERAL_FRAME
from sds_sloshing.surface_series import RecordingError
from sds_tracker.line import LineProfile
from sds_tracker.spots import is_measured
from sds_tracker.tracker import FrameTracker, TrackedSpot, parse_seeds, tracker_config

GRAPH = CONFIG / "graphs" / "drop.yaml"
"""The graph whose tracker and reconstruction parameters the pipeline uses by default."""
FRAMES_BEFORE_MODEL = 90
"""Camera frames a recording may hold before its first camera model (3 s at 30 fps; the
recorder logs the latched model once it matches, about 3 frames late in the graph's tests)."""


@dataclass(frozen=True)
class RedFrame:
    """A frame's red channel (the region only), its region offset [px] and time [s]."""

    index: int
    time_s: float
    red: np.ndarray
    offset: tuple[int, int]


LOSSLESS_CODECS = ("rawvideo", "png", "ffv1")
"""Video codecs that keep every pixel (H.264 may too, at qp 0, but its stream does not say)."""


def damping_caveat(video: Path) -> str:
    """What a compressed video file does to the damping ratios, for the analysis's notes
    (nothing for an image folder, a camera or a lossless codec): bench/README.md, "Damping
    ratios and the video's rate"."""
    if not video.is_file():
        return ""
    with closing(VideoFileSource(video)) as source:
        codec = source.codec
    if codec in LOSSLESS_CODECS:
        return ""
    return (f"{codec} video: compression shrinks sub-pixel spot motion, so the damping ratio "
            "may read a few % high, beyond its σ (record at the camera's highest bit rate)")


def video_frames(path: Path, rig: Rig, fps: float = 0.0) -> Iterator[RedFrame]:
    """A video's frames, the container's region (Rig.container_region_px) in red; the video
    is opened and checked here (its frame size is the rig's camera's), before the first
    frame is asked for."""
    source = open_source(str(path), fps=fps)
    region = Region(*rig.container_region_px(rig.camera))
    camera = rig.camera
    try:
        if (source.width, source.height) != (camera.width_px, camera.height_px):
            raise FrameSourceError(
                f"{path}: frames of {source.width}x{source.height} px, but the rig's camera "
                f"({rig.camera_file or 'rig file'}) is {camera.width_px}x{camera.height_px} px: "
                "the rig of another camera or resolution?")
        region.check_inside(source.width, source.height)
    except FrameSourceError:
        source.close()
        raise
    return read_ahead(_red_frames(source, region))


def _red_frames(source: FrameSource, region: Region) -> Iterator[RedFrame]:
    """The region's red channel of each frame (a video converts only that region)."""
    try:
        for frame in source.frames(region, "red"):
            yield RedFrame(frame.index, frame.time_ns * 1e-9, frame.image, (region.x, region.y))
    finally:
        source.close()


IMAGE_TYPE = "sensor_msgs/msg/Image"
MODEL_TYPE = "sds_msgs/msg/CameraModel"


def mcap_frames(path: Path) -> Iterator[RedFrame]:
    """A recording's camera frames and the region its camera model gives: decoded from the
    camera's packets (`PACKET_TYPES`) when it has them, all that the camera sent (also those
    the live chain shed), else its frames (sensor_msgs/Image); a recording with neither is
    refused here, before the first frame is asked for."""
    types = {type_name for type_name, _ in recorded_topics(path).values()}
    packets = [t for t in PACKET_TYPES if t in types]
    if packets:
        return read_ahead(_decoded_packets(path, packets[0]))
    if IMAGE_TYPE not in types:
        raise RecordingError(f"{path}: the recording has no camera frames (sensor_msgs/Image) "
                             f"or packets ({', '.join(PACKET_TYPES)})")
    return read_ahead(_recorded_frames(path))


def _top_camera_messages(path: Path, frame_type: str) -> Iterator[tuple[Any, Any]]:
    """The top camera's models and messages of `frame_type` in recorded order, as (model, None)
    or (None, message) (the side camera's, frame_id LATERAL_FRAME, left out)."""
    for recorded, msg in decoded_messages(path, types=(MODEL_TYPE, frame_type)):
        frame_id = msg.frame_id if hasattr(msg, "frame_id") else msg.header.frame_id
        if frame_id == LATERAL_FRAME:
            continue
        yield (msg, None) if recorded.type_name == MODEL_TYPE else (None, msg)


def _decoded_packets(path: Path, packet_type: str) -> Iterator[RedFrame]:
    """The frames of the recorded packets, in presentation order, the region of the camera
    model that precedes them in red (packets before any model wait for it, at most
    FRAMES_BEFORE_MODEL of them)."""
    decoder: PacketDecoder | None = None
    model: Any = None
    waiting: list[Any] = []
    first: int | None = None
    for new_model, packet in _top_camera_messages(path, packet_type):
        model = new_model if new_model is not None else model
        if packet is not None:
            waiting.append(packet)
            if model is None and len(waiting) > FRAMES_BEFORE_MODEL:
                raise RecordingError(f"{path}: {len(waiting)} camera packets before any camera "
                                     "model (the region is unknown)")
        if model is None:
            continue
        region = Region(int(model.roi.x_offset), int(model.roi.y_offset),
                        int(model.roi.width), int(model.roi.height))
        for packet in waiting:
            _, stamp, packet_format, data = packet_fields(packet)
            if decoder is None:
                decoder = PacketDecoder(packet_format, region, "red")
            for frame in decoder.decode(VideoPacket(0, stamp, False, data)):
                first = frame.time_ns if first is None else first
                yield RedFrame(frame.index, (frame.time_ns - first) * 1e-9, frame.image,
                               (region.x, region.y))
        waiting.clear()
    if waiting:
        raise RecordingError(f"{path}: camera packets but no camera model (the region is "
                             "unknown)")
    for frame in decoder.flush() if decoder is not None else []:
        first = frame.time_ns if first is None else first
        yield RedFrame(frame.index, (frame.time_ns - first) * 1e-9, frame.image,
                       (int(model.roi.x_offset), int(model.roi.y_offset)))


def _recorded_frames(path: Path) -> Iterator[RedFrame]:
    """The frames in recorded order, each with the latest camera model's region offset; the
    frames before the first model wait for it (a recorder may log the latched model after
    the first frames), at most FRAMES_BEFORE_MODEL of them."""
    offset: tuple[int, int] | None = None
    waiting: list[tuple[int, np.ndarray]] = []   # (stamp [ns], red image) before any model
    first: int | None = None
    index = 0
    for model, msg in _top_camera_messages(path, IMAGE_TYPE):
        if model is not None:
            offset = (int(model.roi.x_offset), int(model.roi.y_offset))
        else:
            image = msg_to_image(msg)
            waiting.append((stamp_ns(msg), image[..., 2] if image.ndim == 3 else image))
            if offset is None and len(waiting) > FRAMES_BEFORE_MODEL:
                raise RecordingError(f"{path}: {len(waiting)} camera frames before any camera "
                                     "model (the region offset is unknown)")
        if offset is not None:
            for stamp, red in waiting:
                first = stamp if first is None else first
                yield RedFrame(index, (stamp - first) * 1e-9, red, offset)
                index += 1
            waiting.clear()
    if waiting:
        raise RecordingError(f"{path}: camera frames but no camera model (the region offset "
                             "is unknown)")


@dataclass(frozen=True)
class SpotFrame:
    """One frame's spots once the Hampel window has released them, with their surface points
    (Eq. 9, as measured), the frame's fits (plane, Eq. 12, and modes) and the points they
    used: at the frame's time (`sds_recon.instant`; the same points for a global shutter)."""

    index: int
    time_s: float
    spots: list[TrackedSpot]
    points: SurfacePoints
    fits: SurfaceFits
    instant_points: SurfacePoints


@dataclass(frozen=True)
class LineFrame:
    """One frame's laser line (a sample per image row) and its surface points (Eqs. 10–11)."""

    index: int
    time_s: float
    line: LineProfile
    points: SurfacePoints


@dataclass(frozen=True)
class PipelineStep:
    """What one frame in gives out: its line at once, and the spot frames the Hampel window
    released (earlier frames; none while the window fills; `flush` gives the rest)."""

    line: LineFrame | None
    spot_frames: list[SpotFrame]


@dataclass(frozen=True)
class TrackedFrame:
    """The tracker's output for one frame, before reconstruction."""

    frame: RedFrame
    released: list[tuple[int, list[TrackedSpot]]]
    line: LineProfile


class FramePipeline:
    """Track, triangulate and fit frame after frame, as the tracker and reconstruction nodes
    do; `run` takes an iterable of frames and yields a PipelineStep per frame, then the
    frames the Hampel window still held."""

    def __init__(self, rig: Rig, tracker_values: Mapping[str, Any] | None = None,
                 recon_values: Mapping[str, Any] | None = None, stills: bool = False) -> None:
        """`tracker_values` and `recon_values`: the nodes' parameters (default: drop.yaml's);
        `stills`: every frame an image of its own surface (no motion prior, no temporal
        filter: each frame's spots come out with it)."""
        tracker_values = node_parameters(GRAPH, "tracker") if tracker_values is None \
            else tracker_values
        if stills:
            tracker_values = {**tracker_values, "stills": True}
        recon_values = node_parameters(GRAPH, "recon") if recon_values is None else recon_values
        self.rig = rig
        self.tracker = FrameTracker(rig, tracker_config(tracker_values),
                                    parse_seeds(tracker_values.get("seeds", [0.0])))
        self.beam_weight = float(recon_values["beam_weight"])
        self.default_sigma_px = float(recon_values["default_sigma_px"])
        self._times_s: dict[int, float] = {}   # frames the Hampel window holds: their times
        self.instant: InstantFits[int] = InstantFits(rig)
        # Frames whose fits wait for the next frame (rolling shutter): time, spots, points.
        self._unfitted: dict[int, tuple[float, list[TrackedSpot], SurfacePoints]] = {}

    def track(self, frame: RedFrame) -> TrackedFrame:
        """The tracker's step: spots of the frames the Hampel window releases, the line now."""
        self._times_s[frame.index] = frame.time_s
        released, line = self.tracker.process(frame.index, frame.red, frame.offset)
        return TrackedFrame(frame, released, line)

    def reconstruct(self, tracked: TrackedFrame) -> PipelineStep:
        """The reconstruction's step: points and fits of the released spots, the line's points."""
        frame, line = tracked.frame, tracked.line
        line_points = reconstruct_line(self.rig, np.column_stack([line.x_px, line.y_px]),
                                       line.sigma_px, self.default_sigma_px)
        return PipelineStep(LineFrame(frame.index, frame.time_s, line, line_points),
                            self._spot_frames(tracked.released))

    def process(self, frame: RedFrame) -> PipelineStep:
        """One frame through tracker and reconstruction."""
        return self.reconstruct(self.track(frame))

    def flush(self) -> PipelineStep:
        """The frames the Hampel window still holds (at the end of the frames)."""
        return PipelineStep(None, self._spot_frames(self.tracker.flush(), end=True))

    def run(self, frames: Iterable[RedFrame]) -> Iterator[PipelineStep]:
        """Every frame's step, then the flush."""
        for frame in frames:
            yield self.process(frame)
        yield self.flush()

    def _spot_frames(self, released: list[tuple[int, list[TrackedSpot]]], end: bool = False
                     ) -> list[SpotFrame]:
        """Triangulate each released frame's spots (Eq. 9) and fit the frames whose fits are
        due (Eq. 12 and the modes, at the frame's time: `sds_recon.instant`); `end`: every
        one left."""
        fitted = []
        for index, spots in released:
            points = frame_points(
                self.rig, [s.laser_id for s in spots], [[s.x_px, s.y_px] for s in spots],
                [s.sigma_px for s in spots], [not is_measured(s.flags) for s in spots],
                self.beam_weight, self.default_sigma_px)
            time_s = self._times_s.pop(index)
            self._unfitted[index] = (time_s, spots, points)
            fitted += self.instant.push(index, time_s, points)
        if end:
            fitted += self.instant.flush()
        spot_frames = []
        for instant in fitted:
            time_s, spots, points = self._unfitted.pop(instant.key)
            spot_frames.append(SpotFrame(instant.key, time_s, spots, points, instant.fits,
                                         instant.points))
        return spot_frames
