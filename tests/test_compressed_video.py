"""The camera's compressed stream: packets read from a file, recorded, and decoded again.

The references are FFmpeg's own reading of the file (PyAV's container decode, no packet of
ours) and an independent MCAP reader (mcap_ros2): the packets' frames must be the file's
frames bit for bit, and what `sds process --mcap` reads from a recording of them the same
frames `sds process --video` reads from the file.
"""

from __future__ import annotations

import gc
import subprocess
import sys
from contextlib import closing
from fractions import Fraction
from pathlib import Path

import av
import numpy as np
import pytest
from builtin_interfaces.msg import Time
from mcap_ros2.reader import read_ros2_messages
from rclpy.serialization import serialize_message
from sds_camera.compressed_video import (
    LivePackets,
    PacketDecoder,
    VideoFilePackets,
    packet_format,
)
from sds_camera.frame_source import FrameSourceError, Region, VideoFileSource
from sds_camera.video_writer import VideoWriter
from sds_record.mcap_files import McapRecorder
from sds_ros.image_msg import packet_msg
from sds_workflows.pipeline import mcap_frames
from sensor_msgs.msg import RegionOfInterest

from sds_msgs.msg import CameraModel

WIDTH, HEIGHT, FRAMES = 320, 240, 24
REGION = Region(41, 23, 201, 151)     # odd corner and size: the chroma alignment matters


def moving_frames() -> list[np.ndarray]:
    """Frames with texture that moves (so that the encoder uses B-frames and motion)."""
    rng = np.random.default_rng(5)
    texture = rng.integers(0, 255, (HEIGHT, WIDTH * 2, 3), dtype=np.uint8)
    return [np.ascontiguousarray(texture[:, 4 * i: 4 * i + WIDTH]) for i in range(FRAMES)]


@pytest.fixture(scope="module")
def h264_video(tmp_path_factory) -> Path:
    """An H.264 file as x264 writes it for a camera (B-frames, in MP4)."""
    path = tmp_path_factory.mktemp("video") / "clip.mp4"
    with VideoWriter(path, WIDTH, HEIGHT, Fraction(30)) as writer:
        for frame in moving_frames():
            writer.write(frame)
    return path


@pytest.fixture(scope="module")
def hevc_video(tmp_path_factory) -> Path:
    """An H.265 file (libx265, in MP4), as newer GoPros record."""
    path = tmp_path_factory.mktemp("video") / "clip_hevc.mp4"
    with av.open(str(path), "w") as container:
        stream = container.add_stream("libx265", rate=30)
        stream.width, stream.height, stream.pix_fmt = WIDTH, HEIGHT, "yuv420p"
        stream.options = {"x265-params": "log-level=error"}
        for image in moving_frames():
            for packet in stream.encode(av.VideoFrame.from_ndarray(image, format="bgr24")):
                container.mux(packet)
        for packet in stream.encode(None):
            container.mux(packet)
    return path


def ffmpeg_frames(path: Path) -> list[tuple[int, np.ndarray]]:
    """The file's frames as FFmpeg decodes the container (times [ns] from the first, BGR)."""
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        frames = [(frame.pts, frame.to_ndarray(format="bgr24"))
                  for frame in container.decode(stream)]
        time_base = stream.time_base
    first = frames[0][0]
    return [(round((pts - first) * time_base * 10**9), image) for pts, image in frames]


@pytest.mark.parametrize("video", ["h264_video", "hevc_video"])
def test_the_packets_decode_to_the_files_frames_bit_for_bit(video: str, request) -> None:
    path = request.getfixturevalue(video)
    packets_of_file = VideoFilePackets(path)
    packets = list(packets_of_file.packets())
    again = list(packets_of_file.packets())        # a second play starts at the beginning
    packets_of_file.close()
    assert [p.data for p in again] == [p.data for p in packets]
    assert len(packets) == FRAMES and packets[0].keyframe
    # Annex B: a start code first; a keyframe carries its parameter sets.
    assert all(p.data.startswith((b"\x00\x00\x01", b"\x00\x00\x00\x01")) for p in packets)
    # Decode order: the frames' times jump about (B-frames), the packets are due in order.
    times = [p.time_ns for p in packets]
    assert sorted(times) == [t for t, _ in ffmpeg_frames(path)]
    assert times != sorted(times)
    assert np.all(np.diff([p.due_ns for p in packets]) > 0) and packets[0].due_ns == 0

    decoder = PacketDecoder(packets_of_file.format)
    decoded = [frame for p in packets for frame in decoder.decode(p)] + decoder.flush()
    reference = ffmpeg_frames(path)
    assert [f.index for f in decoded] == list(range(FRAMES))
    assert [f.time_ns for f in decoded] == [t for t, _ in reference]
    for frame, (_, image) in zip(decoded, reference, strict=True):
        np.testing.assert_array_equal(frame.image, image)

    # A region in one channel: what the frame source decodes for the chain.
    cut = PacketDecoder(packets_of_file.format, REGION, "red")
    regions = [frame for p in packets for frame in cut.decode(p)] + cut.flush()
    source = VideoFileSource(path)
    for frame, expected in zip(regions, source.frames(REGION, "red"), strict=True):
        np.testing.assert_array_equal(frame.image, expected.image)
    source.close()


@pytest.mark.parametrize("video", ["h264_video", "hevc_video"])
def test_a_decoder_catching_up_leaves_out_frames_and_invents_none(video: str, request) -> None:
    """Skipping the frames no other frame refers to (the camera behind real time): fewer
    frames, each the file's own frame at its time bit for bit; once the decoder stops
    skipping, every later packet's frame comes again."""
    path = request.getfixturevalue(video)
    packets_of_file = VideoFilePackets(path)
    packets = list(packets_of_file.packets())
    packets_of_file.close()
    reference = dict(ffmpeg_frames(path))
    decoder = PacketDecoder(packets_of_file.format)
    decoder.skipping_non_reference = True
    half = FRAMES // 2
    while_skipping = [frame for p in packets[:half] for frame in decoder.decode(p)]
    decoder.skipping_non_reference = False
    after = [frame for p in packets[half:] for frame in decoder.decode(p)] + decoder.flush()
    times = [frame.time_ns for frame in while_skipping + after]
    assert len(times) < FRAMES and len(set(times)) == len(times)
    assert {p.time_ns for p in packets[half:]} <= {frame.time_ns for frame in after}
    assert [frame.index for frame in while_skipping + after] == list(range(len(times)))
    for frame in while_skipping + after:
        np.testing.assert_array_equal(frame.image, reference[frame.time_ns])


DROPPED_MID_STREAM = """
import sys, threading
from sds_camera.compressed_video import PacketDecoder, VideoFilePackets
packets = VideoFilePackets(sys.argv[1])
first = [packet for _, packet in zip(range(5), packets.packets())]
packets.close()
def decode_and_drop():
    decoder = PacketDecoder(packets.format)
    for packet in first:
        decoder.decode(packet)
for _ in range(20):
    thread = threading.Thread(target=decode_and_drop)
    thread.start()
    thread.join()
"""


def test_a_decoder_dropped_mid_stream_in_a_thread_does_not_hang_the_process(
        h264_video: Path) -> None:
    """A frame-threaded decoder dropped while it still holds frames, in a thread (the frame
    source's decode thread when its graph stops): freed as it was, FFmpeg waited for its
    frame threads while PyAV held the GIL one of them waited for, and the process hung for
    good (2 of 3 runs of this test, five drops each). Here it is drained first: twenty drops
    in a row end at once."""
    done = subprocess.run([sys.executable, "-c", DROPPED_MID_STREAM, str(h264_video)],
                          capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0, done.stderr


@pytest.mark.filterwarnings("error::pytest.PytestUnraisableExceptionWarning")
@pytest.mark.parametrize("refused", [{"packet_format": "mjpeg"}, {"channel": "infrared"}])
def test_a_decoder_refused_at_its_start_leaves_nothing_to_drain(refused: dict) -> None:
    """A decoder whose format or channel is refused is dropped half made: its drain at the
    end (`PacketDecoder.__del__`) finds no codec and does nothing, instead of an error that
    Python can only print ("Exception ignored in __del__")."""
    arguments = {"packet_format": "h264", **refused}
    with pytest.raises(FrameSourceError, match="is not one of"):
        PacketDecoder(**arguments)
    gc.collect()


def test_a_codec_whose_packets_are_not_carried_is_said(tmp_path: Path) -> None:
    """Motion JPEG in a file: its frames are read, its packets are refused by name."""
    path = tmp_path / "clip.avi"
    with av.open(str(path), "w") as container:
        stream = container.add_stream("mjpeg", rate=30)
        stream.width, stream.height, stream.pix_fmt = WIDTH, HEIGHT, "yuvj420p"
        for image in moving_frames()[:3]:
            for packet in stream.encode(av.VideoFrame.from_ndarray(image, format="bgr24")):
                container.mux(packet)
        for packet in stream.encode(None):
            container.mux(packet)
    with closing(VideoFileSource(path)) as source:
        assert packet_format(source.codec) is None and len(list(source.frames())) == 3
    with pytest.raises(FrameSourceError, match="is mjpeg: only the packets of h264, hevc"):
        VideoFilePackets(path)
    with pytest.raises(FrameSourceError, match="packet format 'mjpeg'"):
        PacketDecoder("mjpeg")


def record_packets(path: Path, video: Path) -> int:
    """A recording as the drop graph makes it: the camera model (the region, red) and the
    file's packets on /camera/video, stamped 1000 s + their frames' times."""
    recorder = McapRecorder(path)
    recorder.add_topic("/camera/camera_model", "sds_msgs/msg/CameraModel", latched=True)
    recorder.add_topic("/camera/video", "foxglove_msgs/msg/CompressedVideo")
    model = CameraModel(channel="red", full_width=WIDTH, full_height=HEIGHT,
                        roi=RegionOfInterest(x_offset=REGION.x, y_offset=REGION.y,
                                             width=REGION.width, height=REGION.height))
    recorder.write("/camera/camera_model", serialize_message(model), 1, 1)
    packets = VideoFilePackets(video)
    count = 0
    for packet in packets.packets():
        stamp_ns = 1000 * 10**9 + packet.time_ns
        msg = packet_msg(packet.data, Time(sec=stamp_ns // 10**9,
                                                 nanosec=stamp_ns % 10**9),
                               "camera_optical", packets.format)
        recorder.write("/camera/video", serialize_message(msg), 2 + count, 2 + count)
        count += 1
    packets.close()
    recorder.close()
    return count


def test_a_recording_of_packets_gives_the_files_frames(tmp_path: Path, h264_video: Path) -> None:
    recording = tmp_path / "packets.mcap"
    assert record_packets(recording, h264_video) == FRAMES
    # An independent reader finds each packet, as Foxglove's schema names it.
    read = [m for m in read_ros2_messages(str(recording), topics=["/camera/video"])]
    assert [m.schema.name for m in read] == ["foxglove_msgs/msg/CompressedVideo"] * FRAMES
    with closing(VideoFilePackets(h264_video)) as packets:
        assert [bytes(m.ros_msg.data) for m in read] == [p.data for p in packets.packets()]
    assert {m.ros_msg.format for m in read} == {"h264"}

    frames = list(mcap_frames(recording))
    with closing(VideoFileSource(h264_video)) as source:
        expected = list(source.frames(REGION, "red"))
    assert [f.index for f in frames] == list(range(FRAMES))
    assert [f.offset for f in frames] == [(REGION.x, REGION.y)] * FRAMES
    assert [round(f.time_s * 1e9) for f in frames] == [f.time_ns for f in expected]
    for frame, reference in zip(frames, expected, strict=True):
        np.testing.assert_array_equal(frame.red, reference.image)


def write_stream(path: Path, codec: str, container_format: str, pixel_format: str) -> None:
    """The moving frames as a live camera streams them: MPEG-TS H.264 without B-frames (a UVC
    camera's), or Motion JPEG."""
    with av.open(str(path), "w", format=container_format) as container:
        stream = container.add_stream(codec, rate=30)
        stream.width, stream.height, stream.pix_fmt = WIDTH, HEIGHT, pixel_format
        if codec == "libx264":
            stream.options = {"bf": "0", "tune": "zerolatency"}
        for image in moving_frames():
            for packet in stream.encode(av.VideoFrame.from_ndarray(image, format="bgr24")):
                container.mux(packet)
        for packet in stream.encode(None):
            container.mux(packet)


@pytest.mark.parametrize(("codec", "container_format", "pixel_format", "input_format"), [
    ("libx264", "mpegts", "yuv420p", "h264"), ("mjpeg", "avi", "yuvj420p", "mjpeg")])
def test_a_live_cameras_packets_are_read_as_they_come_and_decode_to_its_frames(
        tmp_path: Path, codec: str, container_format: str, pixel_format: str,
        input_format: str) -> None:
    """LivePackets on an FFmpeg input of what a UVC camera sends (its V4L2 input is the same
    demuxing with `input_format`): each packet one frame, due when it comes, the frames
    FFmpeg decodes from the stream; the end of the stream is said."""
    path = tmp_path / f"camera.{container_format}"
    write_stream(path, codec, container_format, pixel_format)
    camera = LivePackets(str(path), input_format, demuxer=container_format)
    assert (camera.width, camera.height) == (WIDTH, HEIGHT)
    packets = []
    with pytest.raises(FrameSourceError, match=f"stopped delivering after {FRAMES} packets"):
        for packet in camera.packets():
            packets.append(packet)
    camera.close()
    assert [p.due_ns for p in packets] == [p.time_ns for p in packets]
    assert packets[0].time_ns == 0 and np.all(np.diff([p.time_ns for p in packets]) > 0)
    assert all(p.keyframe for p in packets) == (input_format == "mjpeg") and packets[0].keyframe
    decoder = PacketDecoder(camera.format, low_delay=True)
    decoded = [frame for p in packets for frame in decoder.decode(p)] + decoder.flush()
    reference = ffmpeg_frames(path)
    assert [f.time_ns for f in decoded] == [t for t, _ in reference]
    for frame, (_, image) in zip(decoded, reference, strict=True):
        np.testing.assert_array_equal(frame.image, image)
    with pytest.raises(FrameSourceError, match="input format 'yuyv422'"):
        LivePackets(str(path), "yuyv422")
