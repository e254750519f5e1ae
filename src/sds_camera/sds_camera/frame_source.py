"""Frame sources (video file, V4L2 camera, image folder) with region and channel selection.

Pure module: PyAV (FFmpeg's decoders), OpenCV and numpy only. Pixel convention: x = column,
y = row, origin at the top-left pixel. Times are nanoseconds since the start of the stream.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from fractions import Fraction
from itertools import pairwise
from pathlib import Path
from typing import Protocol, TypeVar

import av
import cv2
import numpy as np
from sds_model.errors import InputError

CHANNELS = ("bgr", "red", "green", "blue", "gray")
IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".bmp", ".jpg", ".jpeg", ".pgm", ".ppm")
_CHANNEL_INDEX = {"blue": 0, "green": 1, "red": 2}


T = TypeVar("T")
READ_AHEAD = 3
"""Frames decoded ahead of their consumer by `read_ahead`."""


class FrameSourceError(InputError):
    """A source that cannot be opened or that ended before its announced length."""


@dataclass(frozen=True)
class Region:
    """Rectangle of the full frame [px]: top-left corner (x, y), width and height."""

    x: int
    y: int
    width: int
    height: int

    @classmethod
    def full(cls, width: int, height: int) -> Region:
        """The whole frame."""
        return cls(0, 0, width, height)

    def check_inside(self, width: int, height: int) -> None:
        """Raise FrameSourceError unless the region lies inside a width x height frame."""
        if self.width <= 0 or self.height <= 0 or self.x < 0 or self.y < 0:
            raise FrameSourceError(f"region {self} must have x, y >= 0 and a positive size")
        if self.x + self.width > width or self.y + self.height > height:
            raise FrameSourceError(f"region {self} does not fit in the {width}x{height} frame")


@dataclass(frozen=True)
class Frame:
    """One frame: its index in the stream, its time since the first frame [ns], its pixels."""

    index: int
    time_ns: int
    image: np.ndarray


class FrameSource(Protocol):
    """What the frame source node reads from."""

    width: int
    height: int
    is_live: bool

    def frames(self, region: Region | None = None, channel: str = "bgr") -> Iterator[Frame]:
        """Yield frames in order, the region (None: whole frame) in the channel (BGR or mono
        as the source gives it for "bgr"); raise FrameSourceError if cut short."""
        ...

    def close(self) -> None:
        """Release the device or file."""
        ...


def select(image: np.ndarray, region: Region, channel: str) -> np.ndarray:
    """Crop a BGR or mono frame to a region and channel, as one C-contiguous array."""
    if channel not in CHANNELS:
        raise FrameSourceError(f"channel {channel!r} is not one of {', '.join(CHANNELS)}")
    crop = image[region.y : region.y + region.height, region.x : region.x + region.width]
    if crop.ndim == 2:
        if channel != "gray":
            raise FrameSourceError(f"channel {channel!r} asked of a monochrome source")
        return np.ascontiguousarray(crop)
    if channel == "bgr":
        return np.ascontiguousarray(crop)
    if channel == "gray":
        return cv2.cvtColor(crop, cv2.COLOR_BGR2GRAY)
    return np.ascontiguousarray(crop[:, :, _CHANNEL_INDEX[channel]])


def _selected(image: np.ndarray, region: Region | None, channel: str) -> np.ndarray:
    """The frame itself when nothing is selected, else the region in the channel."""
    if region is None and channel == "bgr":
        return image
    region = region or Region.full(image.shape[1], image.shape[0])
    region.check_inside(image.shape[1], image.shape[0])
    return select(image, region, channel)


def nominal_fps(stream: av.video.stream.VideoStream) -> float:
    """A video stream's frame rate as its file gives it [fps]; 0 if it gives none."""
    rate = stream.average_rate or stream.guessed_rate
    return float(rate) if rate else 0.0


def announced_frames(container: av.container.InputContainer,
                     stream: av.video.stream.VideoStream) -> int:
    """The frames a video file announces for its stream: its count, else (a file without
    one) its duration times its rate; 0 if it says neither."""
    if stream.frames:
        return stream.frames
    if container.duration is None or not nominal_fps(stream):
        return 0
    return round(container.duration / av.time_base * nominal_fps(stream))


class VideoFileSource:
    """A video file decoded by FFmpeg (PyAV); frame times are the file's own presentation
    times (29.97 fps stays 29.97), from the stream's start."""

    is_live = False

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise FrameSourceError(f"video file {self.path} does not exist")
        try:
            self._container = av.open(str(self.path))
        except av.FFmpegError as error:
            raise FrameSourceError(f"cannot open video {self.path} (corrupt or unsupported: "
                                   f"{error.strerror})") from None
        if not self._container.streams.video:
            self._container.close()
            raise FrameSourceError(f"video {self.path} has no readable video stream")
        self._stream = self._container.streams.video[0]
        self._stream.thread_type = "AUTO"     # frame and slice threads, as many as cores
        self.width = self._stream.codec_context.width
        self.height = self._stream.codec_context.height
        self.codec: str = self._stream.codec_context.name   # FFmpeg's name: "h264", "hevc", …
        self.nominal_fps = nominal_fps(self._stream)
        self.announced_frames = announced_frames(self._container, self._stream)
        if self.width <= 0 or self.height <= 0:
            self._container.close()
            raise FrameSourceError(f"video {self.path} has no readable video stream")

    def frames(self, region: Region | None = None, channel: str = "bgr") -> Iterator[Frame]:
        """Decode every frame, the region (None: whole frame) in the channel; raise
        FrameSourceError if fewer than announced could be read.

        Only the region is converted from the decoder's YUV to BGR (an even-aligned superset,
        so that the chroma samples and the result equal a whole-frame conversion's)."""
        region = region or Region.full(self.width, self.height)
        region.check_inside(self.width, self.height)
        context = self._stream.codec_context
        if context.format is None:
            raise FrameSourceError(f"video {self.path} does not say its pixel format")
        converter = RegionConverter(context.width, context.height, context.format,
                                    self._stream.time_base or Fraction(1, 10**9), region)
        start, time_base = self._stream.start_time, self._stream.time_base
        index = 0
        try:
            for decoded in self._container.decode(self._stream):
                if decoded.pts is None or time_base is None:
                    time_ns = round(index * 1e9 / self.nominal_fps) if self.nominal_fps else 0
                else:
                    start = decoded.pts if start is None else start
                    time_ns = round((decoded.pts - start) * time_base * 10**9)
                yield Frame(index, time_ns, select(*converter.convert(decoded), channel))
                index += 1
        except av.FFmpegError as error:
            raise FrameSourceError(f"video {self.path} failed after {index} frames "
                                   f"(corrupt: {error.strerror})") from None
        if index == 0 or index < self.announced_frames:
            raise FrameSourceError(
                f"video {self.path} ended after {index} of {self.announced_frames} frames "
                "(truncated or corrupt)"
            )

    def close(self) -> None:
        """Release the decoder."""
        self._container.close()


class RegionConverter:
    """FFmpeg's crop and BGR conversion of one region of each decoded frame of a given size
    and pixel format."""

    def __init__(self, width: int, height: int, pixel_format: av.VideoFormat, time_base: Fraction,
                 region: Region) -> None:
        # Chroma is subsampled 2x2 at most: an even corner and size keep the samples aligned.
        x0, y0 = region.x - region.x % 2, region.y - region.y % 2
        crop_width, crop_height = region.x + region.width - x0, region.y + region.height - y0
        crop_width = min(crop_width + crop_width % 2, width - x0)
        crop_height = min(crop_height + crop_height % 2, height - y0)
        self.inner = Region(region.x - x0, region.y - y0, region.width, region.height)
        self._graph = av.filter.Graph()
        chain = [self._graph.add_buffer(width=width, height=height, format=pixel_format,
                                        time_base=time_base),
                 self._graph.add("crop", f"{crop_width}:{crop_height}:{x0}:{y0}:exact=1"),
                 self._graph.add("format", "bgr24"),
                 self._graph.add("buffersink")]
        for upstream, downstream in pairwise(chain):
            upstream.link_to(downstream)
        self._graph.configure()

    @classmethod
    def for_frame(cls, decoded: av.VideoFrame, region: Region) -> RegionConverter:
        """A converter for frames like `decoded`."""
        return cls(decoded.width, decoded.height, decoded.format,
                   decoded.time_base or Fraction(1, 10**9), region)

    def convert(self, decoded: av.VideoFrame) -> tuple[np.ndarray, Region]:
        """The superset's BGR pixels (a view) and where the region lies in them."""
        self._graph.push(decoded)
        converted = self._graph.pull()
        return converted.to_ndarray(), self.inner


class CameraSource:
    """A live camera through OpenCV (V4L2 on Linux); frame times from the capture clock."""

    is_live = True

    def __init__(self, device: str | int, width: int = 0, height: int = 0, fps: float = 0.0):
        self.device = device
        self._capture = cv2.VideoCapture(device, cv2.CAP_V4L2)
        if not self._capture.isOpened():
            raise FrameSourceError(f"cannot open camera {device}")
        if width and height:
            self._capture.set(cv2.CAP_PROP_FRAME_WIDTH, width)
            self._capture.set(cv2.CAP_PROP_FRAME_HEIGHT, height)
        if fps:
            self._capture.set(cv2.CAP_PROP_FPS, fps)
        self.width = int(self._capture.get(cv2.CAP_PROP_FRAME_WIDTH))
        self.height = int(self._capture.get(cv2.CAP_PROP_FRAME_HEIGHT))

    def frames(self, region: Region | None = None, channel: str = "bgr") -> Iterator[Frame]:
        """Grab until the camera stops delivering; time is taken right after each grab."""
        index = 0
        start_ns: int | None = None
        while self._capture.grab():
            now_ns = time.monotonic_ns()
            start_ns = now_ns if start_ns is None else start_ns
            ok, image = self._capture.retrieve()
            if not ok:
                break
            yield Frame(index, now_ns - start_ns, _selected(image, region, channel))
            index += 1
        raise FrameSourceError(f"camera {self.device} stopped delivering after {index} frames")

    def close(self) -> None:
        """Release the device."""
        self._capture.release()


class ImageFolderSource:
    """A folder of images read in name order at a fixed frame rate [fps]."""

    is_live = False

    def __init__(self, folder: str | Path, fps: float) -> None:
        self.folder = Path(folder)
        self.paths = sorted(p for p in self.folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not self.paths:
            raise FrameSourceError(f"no images ({', '.join(IMAGE_SUFFIXES)}) in {self.folder}")
        if fps <= 0:
            raise FrameSourceError("an image folder needs a positive fps")
        self.fps = fps
        first = self._read(self.paths[0])
        self.height, self.width = first.shape[:2]

    def _read(self, path: Path) -> np.ndarray:
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise FrameSourceError(f"cannot read image {path}")
        if image.dtype != np.uint8:
            raise FrameSourceError(f"image {path} is {image.dtype}, only 8-bit images are read")
        if image.ndim == 3 and image.shape[2] == 4:
            image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
        return image

    def frames(self, region: Region | None = None, channel: str = "bgr") -> Iterator[Frame]:
        """Read each image once; a missing or unreadable file raises FrameSourceError."""
        for index, path in enumerate(self.paths):
            image = self._read(path)
            if image.shape[:2] != (self.height, self.width):
                raise FrameSourceError(f"image {path} is not {self.width}x{self.height}")
            yield Frame(index, round(index * 1e9 / self.fps), _selected(image, region, channel))

    def close(self) -> None:
        """Nothing to release."""


def open_source(spec: str, fps: float = 0.0) -> FrameSource:
    """Open a source named by a string: a video file, a folder, /dev/videoN or camera:N."""
    if spec.startswith("camera:"):
        return CameraSource(int(spec.removeprefix("camera:")), fps=fps)
    if spec.startswith("/dev/video"):
        return CameraSource(spec, fps=fps)
    path = Path(spec)
    if path.is_dir():
        return ImageFolderSource(path, fps)
    return VideoFileSource(path)


def read_ahead(items: Iterator[T], depth: int = READ_AHEAD) -> Iterator[T]:
    """The same items, produced by a background thread up to `depth` ahead, so that decoding
    (OpenCV releases the GIL) overlaps the consumer's work; the producer's error is raised
    at its place in the stream, and a consumer that stops early stops the thread."""
    buffer: queue.Queue[tuple[str, object]] = queue.Queue(maxsize=depth)
    stop = threading.Event()

    def put(kind: str, value: object) -> None:
        while not stop.is_set():
            try:
                buffer.put((kind, value), timeout=0.1)
                return
            except queue.Full:
                continue

    def produce() -> None:
        try:
            for item in items:
                if stop.is_set():
                    return
                put("item", item)
            put("end", None)
        except BaseException as error:  # handed to the consumer, raised there
            put("error", error)

    thread = threading.Thread(target=produce, name="read_ahead", daemon=True)
    thread.start()
    try:
        while True:
            kind, value = buffer.get()
            if kind == "end":
                return
            if kind == "error":
                raise value  # type: ignore[misc]
            yield value  # type: ignore[misc]
    finally:
        stop.set()
        thread.join(timeout=5.0)
