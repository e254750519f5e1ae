"""Compiled (numba) inner loops of the tracker: the spot windows and the line's rows.

Each frame reads only small windows, so the work is a few loops over tens of thousands of
pixels; compiled, they cost well under a millisecond where numpy needed several (bench/).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, fastmath=True)
def spot_windows(image: np.ndarray, corners: np.ndarray, half: int, prior: np.ndarray,
                 threshold: float, min_competitor: float, aperture_factor: float,
                 clip_fraction: float, read_noise: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per window (top-left `corners`, size 2·half + 1): the spot-core centroid in window pixels,
    its σ [px], the raw peak, and whether one clear blob settled it.

    Background: median of the window's border. Blob: the prior-weighted brightest pixel, its
    area and mass above `threshold` within half/2 px; another blob with `min_competitor` of that
    mass leaves the spot to the full search. Centroid: `clip_fraction` of the peak taken off,
    within 1.6 × the blob's radius (`aperture_factor`), re-centred once.
    """
    count = corners.shape[0]
    size = 2 * half + 1
    centres = np.zeros((count, 2))
    sigmas = np.full(count, np.nan)
    peaks = np.zeros(count)
    settled = np.zeros(count, np.bool_)
    border = np.empty(4 * size)
    near2 = (0.5 * half) ** 2
    for k in range(count):
        x0, y0 = corners[k, 0], corners[k, 1]
        for i in range(size):
            border[4 * i] = image[y0, x0 + i]
            border[4 * i + 1] = image[y0 + size - 1, x0 + i]
            border[4 * i + 2] = image[y0 + i, x0]
            border[4 * i + 3] = image[y0 + i, x0 + size - 1]
        background = np.median(border)
        best, gx, gy = -1e30, half, half
        for y in range(size):
            for x in range(size):
                score = (image[y0 + y, x0 + x] - background) * prior[y, x]
                if score > best:
                    best, gx, gy = score, x, y
        area, main, far, peak = 0, 0.0, 0.0, -1e30
        for y in range(size):
            for x in range(size):
                signal = image[y0 + y, x0 + x] - background
                near = (x - gx) ** 2 + (y - gy) ** 2 <= near2
                if near and signal > peak:
                    peak = signal
                if signal > threshold:
                    if near:
                        area += 1
                        main += signal
                    else:
                        far += signal
        if area == 0 or peak <= threshold or far >= min_competitor * max(main, 1e-9):
            continue
        radius = max(aperture_factor * np.sqrt(area / np.pi), 3.0)
        radius2 = radius * radius
        reach = int(np.ceil(radius)) + 1
        cx, cy, total = float(gx), float(gy), 0.0
        for _ in range(2):
            total, sx, sy = 0.0, 0.0, 0.0
            for y in range(max(0, int(cy) - reach), min(size, int(cy) + reach + 1)):
                for x in range(max(0, int(cx) - reach), min(size, int(cx) + reach + 1)):
                    if (x - cx) ** 2 + (y - cy) ** 2 <= radius2:
                        weight = image[y0 + y, x0 + x] - background - clip_fraction * peak
                        if weight > 0:
                            total += weight
                            sx += weight * x
                            sy += weight * y
            if total <= 0:
                break
            cx, cy = sx / total, sy / total
        if total <= 0 or abs(cx - half) + radius > half or abs(cy - half) + radius > half:
            continue
        variance, top = 0.0, 0.0
        for y in range(max(0, int(cy) - reach), min(size, int(cy) + reach + 1)):
            for x in range(max(0, int(cx) - reach), min(size, int(cx) + reach + 1)):
                distance2 = (x - cx) ** 2 + (y - cy) ** 2
                if distance2 <= radius2:
                    raw = float(image[y0 + y, x0 + x])
                    variance += (raw + read_noise * read_noise) * distance2
                    top = max(top, raw)
        centres[k, 0], centres[k, 1] = cx, cy
        sigmas[k] = np.sqrt(variance / 2) / total
        peaks[k] = top
        settled[k] = True
    return centres, sigmas, peaks, settled


@njit(cache=True, fastmath=True)
def line_rows(image: np.ndarray, rows: np.ndarray, starts: np.ndarray, width: int, core: int,
              edges: int, clip_fraction: float, threshold: float, read_noise: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per row: the line's centre (NaN if none), its σ [px], the peak and the raw maximum.

    The band `starts[k]`…+`width` of row `rows[k]`; background = mean of its `edges` outer
    columns on each side; centre = centroid of the core (±`core` columns around the brightest)
    after `clip_fraction` of the peak is taken off.
    """
    count = rows.shape[0]
    centres = np.full(count, np.nan)
    sigmas = np.full(count, np.nan)
    peaks = np.zeros(count)
    tops = np.zeros(count)
    for k in range(count):
        row, start = rows[k], starts[k]
        background = 0.0
        for j in range(edges):
            background += float(image[row, start + j]) + float(image[row, start + width - 1 - j])
        background /= 2 * edges
        brightest, best = -1.0, 0
        for j in range(width):
            if image[row, start + j] > brightest:
                brightest, best = float(image[row, start + j]), j
        best = min(max(best, core), width - 1 - core)
        peak = image[row, start + best] - background
        if peak <= threshold:
            continue
        total, sx = 0.0, 0.0
        for j in range(best - core, best + core + 1):
            weight = image[row, start + j] - background - clip_fraction * peak
            if weight > 0:
                total += weight
                sx += weight * (start + j)
        if total <= 0:
            continue
        centre = sx / total
        variance = 0.0
        for j in range(best - core, best + core + 1):
            if image[row, start + j] - background - clip_fraction * peak > 0:
                variance += (float(image[row, start + j]) + read_noise * read_noise) * \
                    (start + j - centre) ** 2
        centres[k] = centre
        sigmas[k] = np.sqrt(variance) / total
        peaks[k] = peak + background
        tops[k] = brightest
    return centres, sigmas, peaks, tops


def warm_up() -> None:
    """Compile (or load from numba's cache) both kernels now, not on the first frames."""
    image = np.zeros((64, 64), np.uint8)
    spot_windows(image, np.zeros((1, 2), np.int64), 24, np.ones((49, 49)), 30.0, 0.3, 1.6,
                 0.15, 2.0)
    line_rows(image, np.zeros(1, np.int64), np.zeros(1, np.int64), 61, 6, 10, 0.15, 30.0, 2.0)
