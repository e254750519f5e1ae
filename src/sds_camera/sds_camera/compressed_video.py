"""A video's compressed stream: its packets as the camera wrote them, and their decoding.

Pure module: PyAV (FFmpeg) and numpy only. The packets of an H.264 or H.265 file are given in
Annex B (start codes; the parameter sets before each keyframe, by FFmpeg's *_mp4toannexb
filters), as Foxglove's CompressedVideo carries them and as a decoder takes them without the
container; `PacketDecoder` makes of them the frames `VideoFileSource.frames` gives, bit for
bit. Times are nanoseconds since the stream's first frame (presentation times: a stream with
B-frames gives its packets in decode order, their times out of order).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

import av
import av.bitstream

from sds_camera.frame_source import (
    CHANNELS,
    Frame,
    FrameSourceError,
    Region,
    RegionConverter,
    announced_frames,
    select,
)

PACKET_FORMATS = {"h264": ("h264", "h264_mp4toannexb"), "hevc": ("h265", "hevc_mp4toannexb")}
"""FFmpeg's codec name → the packets' format (CompressedVideo.format) and the bitstream filter
that gives them in Annex B."""
DECODERS = {"h264": "h264", "h265": "hevc", "jpeg": "mjpeg"}
"""A packet format → FFmpeg's decoder."""
CAMERA_FORMATS = {"h264": "h264", "mjpeg": "jpeg"}
"""A live camera's compressed output (V4L2's input_format) → its packets' format (H.264 as
CompressedVideo, Motion JPEG as sensor_msgs/CompressedImage: every packet a JPEG)."""
NANOSECOND = Fraction(1, 10**9)


@dataclass(frozen=True)
class VideoPacket:
    """One packet, in decode order: its index in the stream, the presentation time of the frame
    it holds since the stream's first frame [ns], whether it is a keyframe (decoding may start
    there), its bytes, and when it is due [ns] on the same clock: its decode time, which grows
    packet by packet (the presentation times of B-frames do not), moved so that the first
    packet is due at the first frame's time."""

    index: int
    time_ns: int
    keyframe: bool
    data: bytes
    due_ns: int = 0


def packet_format(codec: str) -> str | None:
    """The packets' format of a stream of FFmpeg's codec `codec` ("h264" → "h264", "hevc" →
    "h265"); None when its packets are not carried (another codec: the frames are)."""
    known = PACKET_FORMATS.get(codec)
    return known[0] if known else None


class VideoFilePackets:
    """The packets of a video file's first video stream, read without decoding."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        try:
            self._container = av.open(str(self.path))
        except (av.FFmpegError, OSError) as error:
            raise FrameSourceError(f"cannot open video {self.path} ({error})") from None
        if not self._container.streams.video:
            self._container.close()
            raise FrameSourceError(f"video {self.path} has no readable video stream")
        self._stream = self._container.streams.video[0]
        codec = self._stream.codec_context.name
        if codec not in PACKET_FORMATS:
            self._container.close()
            raise FrameSourceError(f"video {self.path} is {codec}: only the packets of "
                                   f"{', '.join(PACKET_FORMATS)} are carried")
        self.format, self._filter_name = PACKET_FORMATS[codec]
        self._played = False
        self.announced_frames = announced_frames(self._container, self._stream)

    def packets(self) -> Iterator[VideoPacket]:
        """Every packet in file (decode) order, in Annex B, from the start of the file (a
        second call plays it again); FrameSourceError if the file is corrupt or ends before
        the frames its stream announces."""
        if self._played:
            self._container.seek(0, stream=self._stream)
        self._played = True
        annex_b = av.bitstream.BitStreamFilterContext(self._filter_name, self._stream)
        start, time_base = self._stream.start_time, self._stream.time_base
        first_decode: int | None = None
        index = 0
        try:
            for demuxed in self._container.demux(self._stream):
                for packet in annex_b.filter(demuxed if demuxed.size else None):
                    if packet.pts is None or time_base is None:
                        raise FrameSourceError(f"video {self.path}: packet {index} has no "
                                               "presentation time")
                    start = packet.pts if start is None else start
                    decode = packet.dts if packet.dts is not None else packet.pts
                    first_decode = decode if first_decode is None else first_decode
                    yield VideoPacket(index, round((packet.pts - start) * time_base * 10**9),
                                      packet.is_keyframe, bytes(packet),
                                      round((decode - first_decode) * time_base * 10**9))
                    index += 1
        except av.FFmpegError as error:
            raise FrameSourceError(f"video {self.path} failed after {index} packets "
                                   f"(corrupt: {error.strerror})") from None
        if index == 0 or index < self.announced_frames:
            raise FrameSourceError(f"video {self.path} ended after {index} of "
                                   f"{self.announced_frames} packets (truncated or corrupt)")

    def close(self) -> None:
        """Release the file."""
        self._container.close()


class LivePackets:
    """A live camera's compressed packets as its driver gives them, read without decoding:
    H.264 or Motion JPEG from a UVC camera (FFmpeg's V4L2 input with `input_format`), or any
    FFmpeg input of those (`demuxer`, e.g. "h264" for an Annex B stream on a pipe). Times are
    the driver's capture times since the first packet [ns]; a packet is due when it comes."""

    is_live = True

    def __init__(self, device: str, input_format: str, width: int = 0, height: int = 0,
                 fps: float = 0.0, demuxer: str = "v4l2") -> None:
        if input_format not in CAMERA_FORMATS:
            raise FrameSourceError(f"camera input format {input_format!r} is not one of "
                                   f"{', '.join(CAMERA_FORMATS)}")
        options = {"input_format": input_format} if demuxer == "v4l2" else {}
        if width and height:
            options["video_size"] = f"{width}x{height}"
        if fps:
            options["framerate"] = f"{fps:g}"
        self.device, self.format = device, CAMERA_FORMATS[input_format]
        try:
            self._container = av.open(device, format=demuxer, options=options)
        except (av.FFmpegError, OSError) as error:
            raise FrameSourceError(f"cannot open camera {device} for {input_format} "
                                   f"({error})") from None
        if not self._container.streams.video:
            self._container.close()
            raise FrameSourceError(f"camera {device} gives no video stream")
        self._stream = self._container.streams.video[0]
        self.width = self._stream.codec_context.width
        self.height = self._stream.codec_context.height

    def packets(self) -> Iterator[VideoPacket]:
        """Packets as they come, until the camera stops (then FrameSourceError)."""
        time_base = self._stream.time_base or NANOSECOND
        first: int | None = None
        index = 0
        try:
            for packet in self._container.demux(self._stream):
                if not packet.size:
                    break
                pts = packet.pts if packet.pts is not None else 0
                first = pts if first is None else first
                time_ns = round((pts - first) * time_base * 10**9)
                yield VideoPacket(index, time_ns, packet.is_keyframe or self.format == "jpeg",
                                  bytes(packet), time_ns)
                index += 1
        except av.FFmpegError as error:
            raise FrameSourceError(f"camera {self.device} failed after {index} packets "
                                   f"({error.strerror})") from None
        raise FrameSourceError(f"camera {self.device} stopped delivering after {index} packets")

    def frames(self, region: Region | None = None, channel: str = "bgr") -> Iterator[Frame]:
        """The packets decoded, the region in the channel (the FrameSource protocol)."""
        decoder = PacketDecoder(self.format, region, channel)
        for packet in self.packets():
            yield from decoder.decode(packet)

    def close(self) -> None:
        """Release the camera."""
        self._container.close()


class PacketDecoder:
    """Frames from a stream of packets of one format: each frame the region (None: whole) in
    the channel, its time the presentation time its packet carried, its index its place in
    presentation order. The decoder holds packets back (a stream's B-frames; with frame
    threads, one more per thread): `flush` gives the frames it still holds at the end.
    `low_delay` decodes on slice threads only (no frame held for a thread: what a live view
    needs; a stream of one slice per frame then decodes on one core), else on frame and
    slice threads (throughput). `skipping_non_reference` leaves out the frames no other
    frame refers to (a stream's non-reference B-frames: about half of x264's defaults, 40 %
    of the decoding's CPU), so that a decoder behind the camera catches up without a gap up
    to the next keyframe; the frames it gives out meanwhile are exactly those decoded in full,
    and their indices count the frames given out."""

    def __init__(self, packet_format: str, region: Region | None = None,
                 channel: str = "bgr", low_delay: bool = False) -> None:
        self._drained = True   # nothing to drain before the codec exists (`__del__`)
        if packet_format not in DECODERS:
            raise FrameSourceError(f"packet format {packet_format!r} is not one of "
                                   f"{', '.join(DECODERS)}")
        if channel not in CHANNELS:
            raise FrameSourceError(f"channel {channel!r} is not one of {', '.join(CHANNELS)}")
        codec = av.CodecContext.create(DECODERS[packet_format], "r")
        assert isinstance(codec, av.VideoCodecContext)
        self._codec = codec
        self._codec.thread_type = "SLICE" if low_delay else "AUTO"   # threads: as many as cores
        self._region, self._channel = region, channel
        self._converter: RegionConverter | None = None
        self._drained = False
        self.frames_out = 0

    @property
    def skipping_non_reference(self) -> bool:
        """Whether the frames no other frame refers to are left out."""
        return self._codec.skip_frame == "NONREF"

    @skipping_non_reference.setter
    def skipping_non_reference(self, skip: bool) -> None:
        self._codec.skip_frame = "NONREF" if skip else "DEFAULT"   # libavcodec's AVDISCARD_*

    def decode(self, packet: VideoPacket) -> list[Frame]:
        """The frames that this packet completes (none, one, or more after a reordering)."""
        encoded = av.Packet(packet.data)
        encoded.pts, encoded.time_base = packet.time_ns, NANOSECOND
        return self._frames(encoded)

    def flush(self) -> list[Frame]:
        """The frames the decoder still holds; the decoder is done afterwards."""
        self._drained = True
        return self._frames(None)

    def __del__(self) -> None:
        """Drain a decoder dropped before its end (frames discarded). FFmpeg frees a frame-
        threaded decoder that still holds frames by waiting for its threads, and PyAV does
        that holding the GIL, which one of those threads waits for: the process hung for
        good (the frame source's decode thread when a graph stopped mid-stream; the hang of
        PyAV-Org/PyAV#1849). Draining first, with the GIL free, leaves the threads nothing
        to wait for."""
        if not self._drained:
            self._drained = True
            with contextlib.suppress(av.FFmpegError):
                self._codec.decode(None)

    def _frames(self, encoded: av.Packet[Any] | None) -> list[Frame]:
        try:
            decoded = self._codec.decode(encoded)
        except av.FFmpegError as error:
            raise FrameSourceError(f"a packet does not decode ({error.strerror})") from None
        frames = []
        for picture in decoded:
            if self._converter is None:
                region = self._region or Region.full(picture.width, picture.height)
                region.check_inside(picture.width, picture.height)
                self._converter = RegionConverter.for_frame(picture, region)
            pixels, inner = self._converter.convert(picture)
            time_ns = int(picture.pts) if picture.pts is not None else 0
            frames.append(Frame(self.frames_out, time_ns, select(pixels, inner, self._channel)))
            self.frames_out += 1
        return frames
