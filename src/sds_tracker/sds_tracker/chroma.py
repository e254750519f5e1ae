"""Whether an image's red channel repeats one chroma sample over each 2×2 block of pixels.

A 4:2:0 video (H.264 and HEVC as cameras record them) keeps one chroma sample per 2×2
pixels, and a red laser's light is mostly chroma; the frame source's conversion to BGR
repeats each sample over its block, at even full-frame coordinates. The sensor clipped
before the camera averaged the block, so a pixel that shares a block with a saturated one
holds less than its own light: beside a saturated spot on the saturated laser line, only
on the line's side, which moves the spot's centre of symmetry away from the line
(bench/README, "saturated spots on the laser line"). Such a pixel is a lower bound of the
light (`kernels.LOWER_BOUND`).

Within a block neighbouring pixels then differ far less than across the blocks' edges:
over patches along the laser line, the ratio of their mean squared differences was
0.075-0.10 in the camera's H.264 and 0.09-0.15 with every imaging effect, against 0.87-1.27
on the images before the codec (development rigs 7001-7004, 10 frames each; bench/README).
"""

from __future__ import annotations

import numpy as np

from sds_tracker.kernels import KNOWN, LOWER_BOUND, UNKNOWN, border_median

BLOCK_RATIO = 0.4
"""Mean squared difference of neighbouring lit pixels within a 2×2 block over that across
the blocks' edges below which an image has chroma blocks: near the geometric middle of the
development data's 0.15 (with blocks) and 0.87 (without; see the module's docstring)."""
MIN_PAIRS = 500
"""Fewest lit neighbouring pairs within blocks that decide it (20 patches on a line: 1069
at the least on the development data)."""
LINE_PATCHES = 20
"""Patches along the laser line that the ratio is pooled over."""
PATCH_HALF_PX = 8
"""Half size [px] of each patch."""


def block_difference_sums(window: np.ndarray, corner_px: tuple[int, int], threshold: float
                          ) -> np.ndarray:
    """Over the neighbouring pixel pairs (along rows and columns) of `window` (top-left
    pixel at full-frame `corner_px`) that are both `threshold` above the median of its
    border: the summed squared difference and the count of the pairs within one 2×2 block
    (at even full-frame coordinates), then of those across the blocks' edges."""
    values = window.astype(np.float64)
    lit = values - border_median(values) > threshold
    sums = np.zeros(4)
    for axis, start in ((1, corner_px[0]), (0, corner_px[1])):
        squares = np.diff(values, axis=axis) ** 2
        both = lit[:, 1:] & lit[:, :-1] if axis == 1 else lit[1:] & lit[:-1]
        within = (np.arange(squares.shape[axis]) + start) % 2 == 0
        within = within[None, :] if axis == 1 else within[:, None]
        sums += (squares[both & within].sum(), np.count_nonzero(both & within),
                 squares[both & ~within].sum(), np.count_nonzero(both & ~within))
    return sums


def has_chroma_blocks(image: np.ndarray, origin: np.ndarray,
                      line: tuple[np.ndarray, np.ndarray], threshold: float) -> bool | None:
    """Whether `image` (the red channel of the region at full-frame `origin`, x y) has chroma
    blocks, from LINE_PATCHES patches along the laser `line` (full-frame rows, ascending,
    and columns); None where they hold fewer than MIN_PAIRS lit pairs within blocks."""
    rows, columns = line
    size = 2 * PATCH_HALF_PX + 1
    sums = np.zeros(4)
    for index in np.unique(np.linspace(0, len(rows) - 1, LINE_PATCHES).round().astype(int)):
        x0 = int(np.rint(columns[index] - origin[0])) - PATCH_HALF_PX
        y0 = int(np.rint(rows[index] - origin[1])) - PATCH_HALF_PX
        if x0 < 0 or y0 < 0 or x0 + size > image.shape[1] or y0 + size > image.shape[0]:
            continue
        sums += block_difference_sums(image[y0:y0 + size, x0:x0 + size],
                                      (x0 + int(origin[0]), y0 + int(origin[1])), threshold)
    within, within_pairs, across, across_pairs = sums
    if within_pairs < MIN_PAIRS or across_pairs == 0 or across == 0:
        return None
    return bool(within / within_pairs < BLOCK_RATIO * across / across_pairs)


def pixel_states(unknown: np.ndarray, corner_px: tuple[int, int] | None) -> np.ndarray:
    """Each pixel's state (`kernels.KNOWN`, LOWER_BOUND, UNKNOWN) in a window, from its
    `unknown` pixels: where the image has chroma blocks (`corner_px`, the window's top-left
    pixel in full-frame px; None without blocks), the other pixels of an unknown pixel's
    block are lower bounds, the rest known."""
    states = np.where(unknown, UNKNOWN, KNOWN).astype(np.uint8)
    if corner_px is None or not unknown.any():
        return states
    height, width = unknown.shape
    x_shift, y_shift = corner_px[0] % 2, corner_px[1] % 2
    rows, columns = -(-(height + y_shift) // 2), -(-(width + x_shift) // 2)
    padded = np.zeros((2 * rows, 2 * columns), bool)
    padded[y_shift:y_shift + height, x_shift:x_shift + width] = unknown
    blocks = padded.reshape(rows, 2, columns, 2).any(axis=(1, 3))
    shared = np.repeat(np.repeat(blocks, 2, axis=0), 2, axis=1)[y_shift:y_shift + height,
                                                                x_shift:x_shift + width]
    states[shared & ~unknown] = LOWER_BOUND
    return states
