"""A red channel's 2×2 chroma blocks, and a saturated spot on the saturated laser line seen
through them (sds_tracker.chroma)."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from sds_camera.frame_source import VideoFileSource
from sds_camera.video_writer import VideoWriter
from sds_tracker.chroma import KNOWN, LOWER_BOUND, UNKNOWN, has_chroma_blocks, pixel_states
from sds_tracker.spots import SpotSettings, SpotTracker, window_without_line

SIZE_PX = 128
LINE_X_PX, LINE_SLOPE = 60.3, 0.02   # the line's centre column on row 0, and per row
HALF = SpotSettings().window_px


def scene(spot_px: tuple[float, float], speckle: float = 0.1, seed: int = 0) -> np.ndarray:
    """A BGR image of a saturated Gaussian spot (σ 2.2 px) on a saturated laser line (σ 1.6
    px), red light with a little green and blue, clipped at 255 as a sensor does, with
    multiplicative noise of `speckle` per pixel."""
    rows, columns = np.indices((SIZE_PX, SIZE_PX), dtype=float)
    line = 420.0 * np.exp(-0.5 * ((columns - LINE_X_PX - LINE_SLOPE * rows) / 1.6) ** 2)
    spot = 900.0 * np.exp(-0.5 * ((columns - spot_px[0]) ** 2 + (rows - spot_px[1]) ** 2)
                          / 2.2**2)
    noise = 1 + speckle * np.random.default_rng(seed).standard_normal((SIZE_PX, SIZE_PX))
    light = (line + spot) * noise
    return np.round(np.clip(np.stack([10 + 0.05 * light, 10 + 0.08 * light, 12 + light],
                                     axis=-1), 0, 255)).astype(np.uint8)


def through_the_camera(bgr: np.ndarray, folder: Path) -> np.ndarray:
    """The red channel of `bgr` after a 4:2:0 H.264 (x264 at constant quality 0: only the
    chroma is subsampled) as the frame source decodes it."""
    path = folder / "scene.mp4"
    with VideoWriter(path, SIZE_PX, SIZE_PX, Fraction(30), crf=0) as writer:
        writer.write(bgr)
    source = VideoFileSource(path)
    try:
        return next(iter(source.frames(channel="red"))).image
    finally:
        source.close()


def line_px() -> tuple[np.ndarray, np.ndarray]:
    """The line's full-frame rows and centre columns."""
    rows = np.arange(SIZE_PX, dtype=float)
    return rows, LINE_X_PX + LINE_SLOPE * rows


def test_a_videos_red_channel_has_chroma_blocks_and_the_sensors_image_has_none(
        tmp_path: Path) -> None:
    bgr = scene((64.5, 64.7))
    decoded = through_the_camera(bgr, tmp_path)
    assert has_chroma_blocks(decoded, np.zeros(2), line_px(), 30.0) is True
    assert has_chroma_blocks(bgr[:, :, 2], np.zeros(2), line_px(), 30.0) is False
    # A line too faint to show it leaves it unknown.
    assert has_chroma_blocks(np.full_like(decoded, 12), np.zeros(2), line_px(), 30.0) is None
    # The tracker finds it once, on the first frame with the line.
    tracker = SpotTracker({1: np.array([[30.0, 30.0], [31.0, 31.0]])})
    assert tracker.settings.chroma_blocks is None
    tracker.update(decoded, (0, 0), line_px())
    assert tracker.settings.chroma_blocks is True


def test_a_blocks_other_pixels_are_lower_bounds_where_one_is_unknown() -> None:
    unknown = np.zeros((4, 5), bool)
    unknown[1, 2] = True
    # Window corner at full-frame (10, 20): blocks start on even columns and rows.
    expected = np.full((4, 5), KNOWN)
    expected[0:2, 2:4] = LOWER_BOUND
    expected[1, 2] = UNKNOWN
    np.testing.assert_array_equal(pixel_states(unknown, (10, 20)), expected)
    # At (11, 21) the window's own column 2 and row 1 start a block.
    expected = np.full((4, 5), KNOWN)
    expected[1:3, 1:3] = LOWER_BOUND
    expected[1, 2] = UNKNOWN
    np.testing.assert_array_equal(pixel_states(unknown, (11, 21)), expected)
    # Without chroma blocks every other pixel is known.
    np.testing.assert_array_equal(pixel_states(unknown, None),
                                  np.where(unknown, UNKNOWN, KNOWN))


SPOTS_PX = [(x, y) for x in (60.9, 61.4, 61.9, 62.4, 63.3, 64.5) for y in (63.2, 64.7)]


def test_a_saturated_spot_on_the_saturated_line_is_centred_through_the_chroma_blocks(
        tmp_path: Path) -> None:
    """Twelve spots 0.6-4.2 px from the line's centre, both saturated, through a 4:2:0 video:
    with the blocks' pixels as lower bounds every centre is within 0.36 px of the truth
    (measured; bound 0.45); read as the spot's light, the block's clipped share moves the
    centre away from the line, 1.6-2.4 px where the spot is 3-4 px from the line (one of
    them not measured at all)."""
    errors: dict[bool, list[float]] = {True: [], False: []}
    _, columns = line_px()
    for spot in SPOTS_PX:
        red = through_the_camera(scene(spot), tmp_path)
        centre = np.array(spot)
        x0, y0 = np.round(centre).astype(int) - HALF
        window = (int(x0), int(y0), int(x0) + 2 * HALF + 1, int(y0) + 2 * HALF + 1)
        for blocks in (True, False):
            found = window_without_line(red, np.zeros(2), window,
                                        columns[window[1]:window[3]] - window[0],
                                        centre + 0.7, SpotSettings(chroma_blocks=blocks))
            errors[blocks].append(np.inf if found is None or not np.isfinite(found.centre).all()
                                  else float(np.hypot(*(found.centre - centre))))
    assert max(errors[True]) < 0.45, errors[True]
    assert max(errors[False]) > 1.5, errors[False]


@pytest.mark.parametrize("corner", [(0, 0), (1, 0), (0, 1), (1, 1)])
def test_lower_bounds_cover_exactly_the_unknown_pixels_blocks(corner: tuple[int, int]) -> None:
    rng = np.random.default_rng(sum(corner))
    unknown = rng.random((9, 11)) < 0.1
    states = pixel_states(unknown, corner)
    for y, x in np.ndindex(unknown.shape):
        block_y, block_x = (y + corner[1]) // 2, (x + corner[0]) // 2
        same = [(v, u) for v, u in np.ndindex(unknown.shape)
                if (v + corner[1]) // 2 == block_y and (u + corner[0]) // 2 == block_x]
        expected = UNKNOWN if unknown[y, x] else \
            LOWER_BOUND if any(unknown[v, u] for v, u in same) else KNOWN
        assert states[y, x] == expected
