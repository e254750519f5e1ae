"""Frame sources (video file, V4L2 camera, image folder) with region and channel selection.

Pure module: OpenCV and numpy only. Pixel convention: x = column, y = row, origin at the
top-left pixel. Times are nanoseconds since the first frame of the stream.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, TypeVar

import cv2
import numpy as np

CHANNELS = ("bgr", "red", "green", "blue", "gray")
IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".bmp", ".jpg", ".jpeg", ".pgm", ".ppm")
_CHANNEL_INDEX = {"blue": 0, "green": 1, "red": 2}


T = TypeVar("T")
READ_AHEAD = 3
"""Frames decoded ahead of their consumer by `read_ahead`."""


class FrameSourceError(RuntimeError):
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

    def frames(self) -> Iterator[Frame]:
        """Yield full frames (BGR or mono) in order; raise FrameSourceError if cut short."""
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


class VideoFileSource:
    """A video file; frame times are the file's own presentation times (29.97 fps stays 29.97)."""

    is_live = False

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise FrameSourceError(f"video file {self.path} does not exist")
        self._capture = cv2.VideoCapture(str(self.path), cv2.CAP_FFMPEG)
        if not self._capture.isOpened():
            raise FrameSourceError(f"cannot open video {self.path} (corrupt or unsupported)")
        self.width = int(self._capture.get(cv2.CAP_PROP_FRAME_WIDTH))
        self.height = int(self._capture.get(cv2.CAP_PROP_FRAME_HEIGHT))
        self.nominal_fps = float(self._capture.get(cv2.CAP_PROP_FPS))
        self.announced_frames = int(self._capture.get(cv2.CAP_PROP_FRAME_COUNT))
        if self.width <= 0 or self.height <= 0:
            raise FrameSourceError(f"video {self.path} has no readable video stream")

    def frames(self) -> Iterator[Frame]:
        """Decode every frame; raise FrameSourceError if fewer than announced could be read."""
        index = 0
        while True:
            ok, image = self._capture.read()
            if not ok:
                break
            time_ms = self._capture.get(cv2.CAP_PROP_POS_MSEC)
            yield Frame(index, round(time_ms * 1e6), image)
            index += 1
        if index == 0 or index < self.announced_frames:
            raise FrameSourceError(
                f"video {self.path} ended after {index} of {self.announced_frames} frames "
                "(truncated or corrupt)"
            )

    def close(self) -> None:
        """Release the decoder."""
        self._capture.release()


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

    def frames(self) -> Iterator[Frame]:
        """Grab until the camera stops delivering; time is taken right after each grab."""
        index = 0
        start_ns: int | None = None
        while self._capture.grab():
            now_ns = time.monotonic_ns()
            start_ns = now_ns if start_ns is None else start_ns
            ok, image = self._capture.retrieve()
            if not ok:
                break
            yield Frame(index, now_ns - start_ns, image)
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

    def frames(self) -> Iterator[Frame]:
        """Read each image once; a missing or unreadable file raises FrameSourceError."""
        for index, path in enumerate(self.paths):
            image = self._read(path)
            if image.shape[:2] != (self.height, self.width):
                raise FrameSourceError(f"image {path} is not {self.width}x{self.height}")
            yield Frame(index, round(index * 1e9 / self.fps), image)

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
