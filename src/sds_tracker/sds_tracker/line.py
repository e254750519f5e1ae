"""The laser line's centre in every image row it crosses, to a fraction of a pixel."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import median_filter

from sds_tracker.kernels import continues_line, line_rows

INTERPOLATED, SATURATED_LINE, LOW_SIGNAL = 1, 2, 4
"""Flag bits, the same as sds_msgs/LaserLineProfile's."""
SEED_MEDIAN_ROWS = 31
"""Rows in the running median that turns per-row brightest columns into the search centre."""
END_ROWS = 3
"""Rows past a line's end that `end_is_dark` reads: a spot that hides the line's end lights
the row next to it."""
SEEK_MEDIAN_ROWS = 61
"""Rows in `seek_line`'s running median of per-row brightest columns: its reach holds spots
beside the line, and a saturated spot is the brightest on about 17 rows of a 4K image (its
ties with the saturated line fall to the leftmost column); the line outvotes it on 61."""


@dataclass(frozen=True)
class LineSettings:
    """Line tracking parameters (config/params/tracker.yaml documents each)."""

    band_px: int = 30               # columns searched on each side of the expected line
    threshold: float = 30.0         # peak above the row's background that makes a sample
    saturation_level: float = 250.0
    continuity_px: float = 2.0      # farthest a sample may stray from its neighbours' median
    continuity_rows: int = 7        # neighbours on each side for that median
    core_px: int = 6                # columns on each side of the peak in the centroid
    clip_fraction: float = 0.15     # share of the peak removed before the centroid


@dataclass(frozen=True)
class LineProfile:
    """Full-frame line centre per row: x, y, uncertainty [px], peak, flags (rows with a sample)."""

    x_px: np.ndarray
    y_px: np.ndarray
    sigma_px: np.ndarray
    peak: np.ndarray
    flags: np.ndarray


def track_line(image: np.ndarray, offset: tuple[int, int], expected_x: np.ndarray,
               rows: np.ndarray, settings: LineSettings | None = None,
               read_noise: float = 2.0) -> LineProfile:
    """Line centre per row: centroid of the profile's core around its brightest column.

    `rows` are full-frame rows and `expected_x` the line's expected column on each (e.g. the
    previous frame's, or the rig's flat-surface line). `clip_fraction` of the peak is taken off
    the background-subtracted profile first, leaving its symmetric core: a plain centre of mass
    would be pulled by the background and by the window's edges. (A three-point Gaussian fit
    is exact without noise but three times noisier with speckle: 0.32 against 0.09 px RMS on
    the simulator's default drop.) Rows that stray from their neighbours are left out.
    """
    s = settings or LineSettings()
    x0, y0 = offset
    local_rows = np.asarray(rows, dtype=int) - y0
    keep = (local_rows >= 0) & (local_rows < image.shape[0]) & np.isfinite(expected_x)
    local_rows, centre = local_rows[keep], np.asarray(expected_x, dtype=float)[keep] - x0
    empty = np.zeros(0)
    if len(local_rows) == 0:
        return LineProfile(empty, empty, empty, empty, np.zeros(0, np.uint8))
    width = 2 * s.band_px + 1
    if image.shape[1] < width:
        return LineProfile(empty, empty, empty, empty, np.zeros(0, np.uint8))
    start = np.clip(np.round(centre).astype(np.int64) - s.band_px, 0, image.shape[1] - width)
    x, sigma, peak, top = line_rows(image, local_rows.astype(np.int64), start, width,
                                    s.core_px, s.band_px // 3, s.clip_fraction, s.threshold,
                                    read_noise)
    x = x + x0
    flags = np.where(top >= s.saturation_level, SATURATED_LINE, 0).astype(np.uint8)
    x = _without_islands(_continuous(x, s), local_rows, s)
    found = np.isfinite(x)
    return LineProfile(x[found], (local_rows + y0)[found].astype(float), sigma[found],
                       peak[found], flags[found])


def _continuous(x: np.ndarray, s: LineSettings) -> np.ndarray:
    """NaN where a row's centre strays from the running median of the rows around it."""
    finite = np.isfinite(x)
    if finite.sum() < 3:
        return x
    index = np.arange(len(x))
    filled = np.interp(index, index[finite], x[finite])
    median = median_filter(filled, size=2 * s.continuity_rows + 1, mode="nearest")
    result = x.copy()
    result[np.abs(x - median) > s.continuity_px] = np.nan
    return result


def _without_islands(x: np.ndarray, rows: np.ndarray, s: LineSettings) -> np.ndarray:
    """NaN on every short run of samples (fewer than 2 `continuity_rows` + 1 rows) that is
    cut off from the others: by more than `continuity_rows` rows without a sample, or by a
    step across the line of more than 3 `continuity_px` beyond its slope (the median of its
    samples' steps). Such a run is a blob beside the line's end (a wall reflection: one 12
    rows long stood 19 px beside a 35° still's line, 4 rows beyond its end) or a speckle
    grain, not the line, which is long; the running median cannot tell such a run from the
    line where it is all there is on its rows."""
    found = np.flatnonzero(np.isfinite(x))
    if len(found) < 2:
        return x
    row_steps = np.diff(rows[found]).astype(float)
    column_steps = np.diff(x[found])
    slope = float(np.median(column_steps / row_steps))
    cut = (row_steps > s.continuity_rows + 1) | \
        (np.abs(column_steps - slope * row_steps) > 3 * s.continuity_px)
    breaks = np.flatnonzero(cut) + 1
    runs = np.split(found, breaks)
    if len(runs) < 2:
        return x
    result = x.copy()
    for run in runs:
        if rows[run[-1]] - rows[run[0]] + 1 < 2 * s.continuity_rows + 1:
            result[run] = np.nan
    return result


def continued_within(line: LineProfile, first_row: float, last_row: float,
                     settings: LineSettings | None = None) -> LineProfile:
    """The line's samples on the rows `first_row` to `last_row` (full frame), and beyond them
    those that continue it: walking out from its last sample within them, each no more than
    `continuity_rows` + 1 rows past the one before it and within `continuity_px` of the
    straight line through the 2 `continuity_rows` + 1 samples before it; the walk stops at
    the first that is not. Beyond where the line usually ends it is taken only as its own
    continuation, not from a spot on its way past its end (the development stills' rig 7109:
    the line measured 20 rows past its end, over a saturated spot there) or a reflection
    there."""
    s = settings or LineSettings()
    rows, x = line.y_px, line.x_px
    inside = np.flatnonzero((rows >= first_row) & (rows <= last_row))
    if len(inside) < 2:
        return LineProfile(x[inside], rows[inside], line.sigma_px[inside], line.peak[inside],
                           line.flags[inside])
    fit_samples = 2 * s.continuity_rows + 1
    gap_rows = float(s.continuity_rows + 1)
    low, high = int(inside[0]), int(inside[-1])
    while low > 0 and continues_line(rows, x, low - 1, low, min(low + fit_samples, high + 1) - 1,
                                     gap_rows, s.continuity_px):
        low -= 1
    while high < len(rows) - 1 and continues_line(rows, x, high + 1,
                                                  max(high + 1 - fit_samples, low), high,
                                                  gap_rows, s.continuity_px):
        high += 1
    kept = slice(low, high + 1)
    return LineProfile(x[kept], rows[kept], line.sigma_px[kept], line.peak[kept],
                       line.flags[kept])


def end_is_dark(image: np.ndarray, offset: tuple[int, int], line: LineProfile, step: int,
                settings: LineSettings) -> bool:
    """Whether the line really ends at its last sample (`step` 1) or its first (`step` −1):
    on the END_ROWS rows past it, the pixels within a pixel of its end's column stay within
    `threshold` of their row's median over the band (2 `band_px` + 1 columns). False where
    they are lit, as by a spot whose light hides the line's end, or lie outside the image.
    """
    end = -1 if step > 0 else 0
    column = round(float(line.x_px[end])) - offset[0]
    past = int(line.y_px[end]) - offset[1] + step   # the row next to the end
    first = past if step > 0 else past - (END_ROWS - 1)
    last = first + END_ROWS - 1
    x0, x1 = column - settings.band_px, column + settings.band_px + 1
    if first < 0 or last >= image.shape[0] or x0 < 0 or x1 > image.shape[1]:
        return False
    band = image[first:last + 1, x0:x1].astype(np.float32)
    # The middle of an odd count: the row's median.
    median = np.partition(band, settings.band_px, axis=1)[:, settings.band_px]
    near = band[:, settings.band_px - 1:settings.band_px + 2].max(axis=1)
    return bool(np.all(near - median <= settings.threshold))


def redness(bgr: np.ndarray) -> np.ndarray:
    """R − (G + B)/2, floored at 0 (float32): a red laser on a white or grey target.

    On white paper the red channel alone sits near saturation with or without the laser;
    subtracting the other channels leaves the laser and removes the target's print.
    """
    blue, green, red = cv2.split(bgr.astype(np.float32))
    return np.maximum(red - 0.5 * (green + blue), 0.0)


def seek_line(image: np.ndarray, offset: tuple[int, int], rows: np.ndarray,
              low_x: np.ndarray, high_x: np.ndarray, settings: LineSettings | None = None,
              read_noise: float = 2.0) -> LineProfile:
    """The line anywhere between full-frame columns `low_x` and `high_x` on each of the
    full-frame `rows`, with no prior inside that reach (a still, or a video's first frame).

    Each row's brightest column in its reach, on the rows whose brightest rises `threshold`
    above the row's mean, smoothed by a running median over SEEK_MEDIAN_ROWS rows (so that
    a spot beside the line cannot move the search), is the centre that `track_line` refines.
    """
    s = settings or LineSettings()
    x0, y0 = offset
    local_rows = np.asarray(rows, dtype=np.int64) - y0
    keep = (local_rows >= 0) & (local_rows < image.shape[0]) & np.isfinite(low_x) & \
        np.isfinite(high_x)
    local_rows = local_rows[keep]
    low = np.clip(np.floor(np.asarray(low_x)[keep]) - x0, 0, image.shape[1]).astype(np.int64)
    high = np.clip(np.ceil(np.asarray(high_x)[keep]) - x0 + 1, 0, image.shape[1]
                   ).astype(np.int64)
    width = int(np.max(high - low)) if len(local_rows) else 0
    if width <= 0:
        empty = np.zeros(0)
        return LineProfile(empty, empty, empty, empty, np.zeros(0, np.uint8))
    starts = np.clip(low, 0, image.shape[1] - width)
    columns = starts[:, None] + np.arange(width)
    inside = (columns >= low[:, None]) & (columns < high[:, None])
    reach = np.where(inside, image[local_rows[:, None], columns], 0)
    brightest = np.argmax(reach, axis=1)
    # The row's mean stands for its background: the line and a spot or two are a few % of it.
    background = reach.sum(axis=1, dtype=np.float64) / np.maximum(inside.sum(axis=1), 1)
    lit = reach[np.arange(len(local_rows)), brightest] - background > s.threshold
    if lit.sum() < 2:
        empty = np.zeros(0)
        return LineProfile(empty, empty, empty, empty, np.zeros(0, np.uint8))
    index = np.arange(len(local_rows))
    centre = np.interp(index, index[lit], (starts + brightest)[lit].astype(float))
    centre = median_filter(centre, size=SEEK_MEDIAN_ROWS, mode="nearest")
    return _longest_stretch(track_line(image, offset, centre + x0, local_rows + y0, s,
                                       read_noise), s.band_px)


def _longest_stretch(line: LineProfile, jump_px: float) -> LineProfile:
    """The line's longest stretch of rows without a jump of more than `jump_px` between
    neighbouring samples: beyond the line's ends the median seeks a spot's rows instead."""
    if len(line.x_px) < 2:
        return line
    breaks = np.flatnonzero(np.abs(np.diff(line.x_px)) > jump_px) + 1
    bounds = np.concatenate([[0], breaks, [len(line.x_px)]])
    longest = int(np.argmax(np.diff(bounds)))
    kept = slice(bounds[longest], bounds[longest + 1])
    return LineProfile(line.x_px[kept], line.y_px[kept], line.sigma_px[kept],
                       line.peak[kept], line.flags[kept])


def find_line(image: np.ndarray, mask: np.ndarray, settings: LineSettings | None = None
              ) -> LineProfile:
    """The line's centre per row inside `mask` (same shape, nonzero = searched), no prior.

    For calibration images, where nothing says where the line is: each row's brightest masked
    column, smoothed by a running median over SEED_MEDIAN_ROWS rows (so a stray bright pixel
    cannot move the search), is the centre that `track_line` refines.
    """
    searched = np.where(mask > 0, image, 0)
    rows = np.flatnonzero((mask > 0).any(axis=1))
    if len(rows) == 0:
        empty = np.zeros(0)
        return LineProfile(empty, empty, empty, empty, np.zeros(0, np.uint8))
    brightest = np.argmax(searched[rows], axis=1).astype(float)
    centre = median_filter(brightest, size=SEED_MEDIAN_ROWS, mode="nearest")
    return track_line(searched, (0, 0), centre, rows, settings)
