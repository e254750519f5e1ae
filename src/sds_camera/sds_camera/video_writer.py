"""Write frames to a video file through the ffmpeg binary of the imageio-ffmpeg wheel."""

from __future__ import annotations

import subprocess
from fractions import Fraction
from pathlib import Path
from types import TracebackType

import imageio_ffmpeg
import numpy as np

# Codec settings: "h264" as a camera records (lossy, yuv420p: at a constant quality, or at a
# camera's bit rate), "lossless" keeps every pixel (libx264rgb at qp 0 for BGR, libx264 qp 0
# for mono).
CODECS = ("h264", "lossless")
ENCODER_THREADS = "1"
"""One encoder thread: the same frames give the same file on every run. x264's
threads (frame or slice) under a bit-rate limit (VBV) gave a different file nearly every run,
so a simulated run that went wrong could not be made again."""


class VideoWriter:
    """Pipe 8-bit BGR or mono frames into ffmpeg at a rational frame rate (e.g. 30000/1001)."""

    def __init__(
        self,
        path: str | Path,
        width: int,
        height: int,
        fps: Fraction | float,
        codec: str = "h264",
        mono: bool = False,
        crf: int = 18,
        bitrate_bit_s: float | None = None,
    ) -> None:
        """`bitrate_bit_s` (h264 only): encode at this rate, as a camera does, instead of at
        the constant quality `crf`."""
        if codec not in CODECS:
            raise ValueError(f"codec {codec!r} is not one of {CODECS}")
        rate = Fraction(fps).limit_denominator(100000)
        self.path = Path(path)
        self.shape = (height, width) if mono else (height, width, 3)
        pix_in = "gray" if mono else "bgr24"
        if codec == "lossless":
            out = ["-c:v", "libx264", "-qp", "0", "-pix_fmt", "gray"] if mono else [
                "-c:v", "libx264rgb", "-qp", "0"]
        elif bitrate_bit_s is not None:
            # A camera's encoder holds its rate within about a second's buffer.
            rate_bit_s = str(int(bitrate_bit_s))
            out = ["-c:v", "libx264", "-b:v", rate_bit_s, "-maxrate", rate_bit_s,
                   "-bufsize", rate_bit_s, "-pix_fmt", "yuv420p"]
        else:
            out = ["-c:v", "libx264", "-crf", str(crf), "-pix_fmt", "yuv420p"]
        command = [
            imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error",
            "-f", "rawvideo", "-pix_fmt", pix_in, "-s", f"{width}x{height}",
            "-r", f"{rate.numerator}/{rate.denominator}", "-i", "-",
            *out, "-preset", "veryfast", "-threads", ENCODER_THREADS, str(self.path),
        ]
        self._process = subprocess.Popen(command, stdin=subprocess.PIPE, stderr=subprocess.PIPE)

    def write(self, frame: np.ndarray) -> None:
        """Append one frame of the writer's shape."""
        if frame.shape != self.shape or frame.dtype != np.uint8:
            raise ValueError(f"frame {frame.shape} {frame.dtype} is not {self.shape} uint8")
        assert self._process.stdin is not None
        self._process.stdin.write(np.ascontiguousarray(frame).data)

    def close(self) -> None:
        """Finish the file; raise RuntimeError with ffmpeg's message if encoding failed."""
        assert self._process.stdin is not None and self._process.stderr is not None
        self._process.stdin.close()
        error = self._process.stderr.read().decode(errors="replace")
        if self._process.wait() != 0:
            raise RuntimeError(f"ffmpeg failed writing {self.path}: {error.strip()}")

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()
