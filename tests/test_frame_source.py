"""Frame sources read real files: pixels, presentation times, regions, channels, bad input."""

from __future__ import annotations

import os
import shutil
import threading
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import NTSC, ntsc_time_ns, random_frames, write_lossless_clip
from sds_camera.frame_source import (
    FrameSourceError,
    ImageFolderSource,
    Region,
    VideoFileSource,
    open_source,
    read_ahead,
    select,
)


@pytest.fixture(scope="module")
def frames() -> np.ndarray:
    return random_frames(24, 90, 160, seed=3)


@pytest.fixture(scope="module")
def clip(tmp_path_factory: pytest.TempPathFactory, frames: np.ndarray) -> Path:
    return write_lossless_clip(tmp_path_factory.mktemp("clip") / "ntsc.mp4", frames, NTSC)


def test_video_file_gives_exact_pixels_and_ntsc_presentation_times(clip, frames):
    source = VideoFileSource(clip)
    read = list(source.frames())
    assert [f.index for f in read] == list(range(len(frames)))
    for frame in read:
        np.testing.assert_array_equal(frame.image, frames[frame.index])
        assert abs(frame.time_ns - ntsc_time_ns(frame.index)) <= 1
    assert source.nominal_fps == pytest.approx(float(NTSC))


def test_select_crops_region_and_channel_like_numpy_and_opencv(frames):
    image = frames[0]
    region = Region(10, 20, 64, 48)
    crop = image[20:68, 10:74]
    np.testing.assert_array_equal(select(image, region, "bgr"), crop)
    for name, index in (("blue", 0), ("green", 1), ("red", 2)):
        selected = select(image, region, name)
        assert selected.flags.c_contiguous
        np.testing.assert_array_equal(selected, crop[:, :, index])
    np.testing.assert_array_equal(
        select(image, region, "gray"), cv2.cvtColor(np.ascontiguousarray(crop), cv2.COLOR_BGR2GRAY)
    )


@pytest.mark.parametrize("channel", ["red", "green", "blue", "gray", "bgr"])
def test_a_region_of_h264_equals_opencvs_whole_frame_decode_cropped(tmp_path, frames, channel):
    """Only the region is converted from 4:2:0 YUV (odd corners and sizes too), and the
    pixels and times equal OpenCV's decoding of the whole frame, cropped afterwards."""
    from sds_camera.video_writer import VideoWriter

    path = tmp_path / "lossy.mp4"
    with VideoWriter(path, 160, 90, NTSC) as writer:   # H.264, yuv420p
        for frame in frames:
            writer.write(frame)
    for region in (Region(13, 7, 51, 33), Region(0, 0, 160, 90), Region(159, 89, 1, 1)):
        capture = cv2.VideoCapture(str(path), cv2.CAP_FFMPEG)
        count = 0
        for frame in VideoFileSource(path).frames(region, channel):
            ok, whole = capture.read()
            assert ok
            np.testing.assert_array_equal(frame.image, select(whole, region, channel))
            assert frame.image.flags.c_contiguous
            assert frame.time_ns == round(capture.get(cv2.CAP_PROP_POS_MSEC) * 1e6)
            count += 1
        assert count == len(frames)


@pytest.mark.parametrize(
    "region",
    [Region(0, 0, 161, 10), Region(-1, 0, 10, 10), Region(150, 80, 20, 20), Region(0, 0, 0, 5)],
)
def test_region_outside_the_frame_is_refused(region):
    with pytest.raises(FrameSourceError):
        region.check_inside(160, 90)


def test_unknown_channel_is_refused(frames):
    with pytest.raises(FrameSourceError, match="channel"):
        select(frames[0], Region.full(160, 90), "infrared")


def test_mp4_truncated_before_its_index_fails_with_a_clear_error(tmp_path, clip):
    cut = tmp_path / "cut.mp4"
    shutil.copy(clip, cut)
    os.truncate(cut, cut.stat().st_size // 2)
    with pytest.raises(FrameSourceError, match="cannot open"):
        VideoFileSource(cut)


def test_truncated_stream_keeps_good_frames_and_then_reports_the_cut(tmp_path, frames):
    whole = write_lossless_clip(tmp_path / "whole.mkv", frames, NTSC)
    cut = tmp_path / "cut.mkv"
    shutil.copy(whole, cut)
    os.truncate(cut, int(cut.stat().st_size * 0.6))
    received = []
    with pytest.raises(FrameSourceError, match=r"ended after \d+ of 24 frames"):
        for frame in VideoFileSource(cut).frames():
            received.append(frame)
    assert 0 < len(received) < len(frames)
    for frame in received:
        np.testing.assert_array_equal(frame.image, frames[frame.index])


def test_missing_and_garbage_files_are_refused(tmp_path):
    with pytest.raises(FrameSourceError, match="does not exist"):
        VideoFileSource(tmp_path / "nothing.mp4")
    garbage = tmp_path / "garbage.mp4"
    garbage.write_bytes(np.random.default_rng(0).bytes(10000))
    with pytest.raises(FrameSourceError):
        list(open_source(str(garbage)).frames())


def test_image_folder_in_name_order_at_its_frame_rate(tmp_path, frames):
    for index, frame in enumerate(frames[:5]):
        cv2.imwrite(str(tmp_path / f"frame_{index:04d}.png"), frame)
    source = open_source(str(tmp_path), fps=25.0)
    assert isinstance(source, ImageFolderSource)
    read = list(source.frames())
    assert [f.time_ns for f in read] == [0, 40_000_000, 80_000_000, 120_000_000, 160_000_000]
    for frame in read:
        np.testing.assert_array_equal(frame.image, frames[frame.index])


def test_image_folder_needs_images_and_a_frame_rate(tmp_path):
    with pytest.raises(FrameSourceError, match="no images"):
        ImageFolderSource(tmp_path, 30.0)
    cv2.imwrite(str(tmp_path / "a.png"), np.zeros((4, 4), np.uint8))
    with pytest.raises(FrameSourceError, match="fps"):
        ImageFolderSource(tmp_path, 0.0)


def test_read_ahead_keeps_order_raises_in_place_and_stops_with_its_consumer():
    def frames(fail_at: int | None = None):
        for index in range(20):
            if index == fail_at:
                raise FrameSourceError(f"corrupt at {index}")
            yield index

    assert list(read_ahead(frames())) == list(range(20))
    got = []
    with pytest.raises(FrameSourceError, match="corrupt at 7"):
        for item in read_ahead(frames(fail_at=7)):
            got.append(item)
    assert got == list(range(7))
    stream = read_ahead(frames(), depth=2)
    assert next(stream) == 0
    stream.close()   # the consumer stops: the producer thread ends
    assert not any(t.name == "read_ahead" and t.is_alive() for t in threading.enumerate())
