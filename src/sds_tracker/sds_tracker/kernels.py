"""Compiled (numba) inner loops of the tracker: the spot windows, the line's rows, and a
spot the line overlaps (the line's light removed, the spot's centre of symmetry); and the
window's background they and the spot windows share (`border_median`).

Each frame reads only small windows, so the work is a few loops over tens of thousands of
pixels; compiled, they cost well under a millisecond where numpy needed several (bench/).
"""

from __future__ import annotations

import numpy as np
from numba import njit

KNOWN, LOWER_BOUND, UNKNOWN = 0, 1, 2
"""A pixel's state for a centre of symmetry (`symmetric_centre`): its light is known; at
least what it holds (it shares a chroma block with a saturated pixel:
`chroma.pixel_states`); or unknown (saturated where the laser line lights it)."""
FIXED_APERTURE_PASSES = 8
"""Most passes of a centroid in a fixed aperture (`spot_windows`): started at a spot's
brightest pixel, a grain of speckle up to a few px from its centre. Measured on development
rigs 7001-7002 (clean, speckle, every effect; 3554 spots): settled in 3 passes (median), 5
(90th percentile), 8 for 99.5 % of them."""
FIXED_APERTURE_SETTLED_PX = 0.01
"""A centroid in a fixed aperture that moved less than this in a pass [px] has settled."""


@njit(cache=True)
def background_step(window: np.ndarray, read_noise: float) -> float:
    """How far a window's background departs from one level [grey levels]: the third
    brightest less the third darkest median of its border's eight half-sides, less the read
    noise (a difference within it is noise, not an edge). An edge across the window (the
    container's rim behind a spot near the wall) darkens at least three of them and brightens
    three; the laser line along one side lights only two."""
    height, width = window.shape
    medians = np.empty(8)
    for side in range(4):
        if side < 2:
            values = window[0 if side == 0 else height - 1].astype(np.float64)
        else:
            values = window[:, 0 if side == 2 else width - 1].astype(np.float64)
        middle = len(values) // 2
        medians[2 * side] = np.median(values[:middle])
        medians[2 * side + 1] = np.median(values[middle:])
    medians.sort()
    return max(float(medians[5] - medians[2]) - read_noise, 0.0)


@njit(cache=True)
def light_elongation(image: np.ndarray, cx: float, cy: float, radius: float,
                     background: float, threshold: float) -> float:
    """How elongated the light around (`cx`, `cy`) [image px] is: 1 for a round spot, about
    L/w for a stripe of length L and width w (the container's rim, the laser line). The
    square root of the larger over the smaller eigenvalue of the second moments of the
    signal (image − `background`) above `threshold` within `radius` px, each pixel with its
    own extent (1/12 px²); 1 where no light is there. The light within the circle counts,
    joined or not: a dim stripe that the threshold breaks into short pieces is one stripe.
    The caller's background and threshold are those that made the blob: a brighter region
    beyond an edge, under the threshold, is not the blob's light."""
    reach = int(np.ceil(radius))
    x0, x1 = max(round(cx) - reach, 0), min(round(cx) + reach, image.shape[1] - 1)
    y0, y1 = max(round(cy) - reach, 0), min(round(cy) + reach, image.shape[0] - 1)
    total, sx, sy, sxx, syy, sxy = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    for y in range(y0, y1 + 1):
        for x in range(x0, x1 + 1):
            if (x - cx) ** 2 + (y - cy) ** 2 > radius * radius:
                continue
            signal = float(image[y, x]) - background
            if signal > threshold:
                total += signal
                sx += signal * x
                sy += signal * y
                sxx += signal * x * x
                syy += signal * y * y
                sxy += signal * x * y
    if total <= 0:
        return 1.0
    mx, my = sx / total, sy / total
    a = sxx / total - mx * mx + 1 / 12
    b = syy / total - my * my + 1 / 12
    c = sxy / total - mx * my
    middle, spread = (a + b) / 2, np.sqrt(((a - b) / 2) ** 2 + c * c)
    return float(np.sqrt((middle + spread) / max(middle - spread, 1 / 12)))


@njit(cache=True)
def step_sigma_px(step: float, lever_px: float, total: float) -> float:
    """The centroid's σ [px] from a background `step` [grey levels] across a spot: half the
    step added on one side and taken off the other, over the weighted pixels' distances from
    the centre (their sum `lever_px`, averaged over the edge's direction: 2/π), in the spot's
    weight `total`. A scalar background leaves such an edge in the spot's light."""
    return step / 2 * (2 / np.pi) * lever_px / total


def border_median(window: np.ndarray) -> float:
    """The median of a window's border pixels (its outermost rows and columns): the local
    background under a spot the window holds."""
    return float(np.median(np.concatenate([window[0], window[-1], window[:, 0],
                                           window[:, -1]])))


@njit(cache=True)
def aperture_ring(radius_px: float, window_px: int) -> int:
    """Half size [px] of the square whose border is a fixed aperture's background
    (`ring_median`): twice the aperture's radius, within the spot's window."""
    return min(window_px, int(np.round(2 * radius_px)))


@njit(cache=True)
def ring_median(window: np.ndarray, centre: int, half: int) -> float:
    """Median of the border of the square of half size `half` about (`centre`, `centre`) of
    a window: the background just outside a fixed aperture of radius half/2."""
    values = np.empty(8 * half)
    low, high = centre - half, centre + half
    for i in range(2 * half):
        values[4 * i] = window[low, low + i]
        values[4 * i + 1] = window[high, high - i]
        values[4 * i + 2] = window[high - i, low]
        values[4 * i + 3] = window[low + i, high]
    return float(np.median(values))


@njit(cache=True, fastmath=True)
def spot_windows(image: np.ndarray, corners: np.ndarray, half: int, prior: np.ndarray,
                 threshold: float, min_competitor: float, aperture_factor: float,
                 clip_fraction: float, read_noise: float, max_elongation: float,
                 apertures_px: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per window (top-left `corners`, size 2·half + 1): the spot-core centroid in window pixels,
    its σ [px], the raw peak, the blob's light (its mass above `threshold`), and whether one
    clear blob settled it.

    Background: median of the window's border. Blob: the prior-weighted brightest pixel, its
    area and mass above `threshold` within half/2 px; another blob with `min_competitor` of that
    mass leaves the spot to the full search. Centroid: `clip_fraction` of the peak taken off,
    within 1.6 × the blob's radius (`aperture_factor`), re-centred once; or, where the window's
    `apertures_px` is above 0, nothing taken off within that radius, re-centred until it moves
    less than FIXED_APERTURE_SETTLED_PX (FIXED_APERTURE_PASSES at most). σ: the photons' and the
    read noise's (`read_noise`), and a background that is not one level (`step_sigma_px`).
    Light more elongated than `max_elongation` about the centre (`light_elongation` within
    half/2: a stripe, not a spot) is left to the full search too.
    """
    count = corners.shape[0]
    size = 2 * half + 1
    centres = np.zeros((count, 2))
    sigmas = np.full(count, np.nan)
    peaks = np.zeros(count)
    lights = np.zeros(count)
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
        fixed = apertures_px[k] > 0
        radius = apertures_px[k] if fixed else max(aperture_factor * np.sqrt(area / np.pi), 3.0)
        # The background just outside a fixed aperture; a clipped centroid's floor.
        floor = ring_median(image[y0:y0 + size, x0:x0 + size], half,
                            aperture_ring(radius, half)) if fixed else \
            float(background + clip_fraction * peak)
        radius2 = radius * radius
        reach = int(np.ceil(radius)) + 1
        cx, cy, total = float(gx), float(gy), 0.0
        for _ in range(FIXED_APERTURE_PASSES if fixed else 2):
            total, sx, sy = 0.0, 0.0, 0.0
            for y in range(max(0, int(cy) - reach), min(size, int(cy) + reach + 1)):
                for x in range(max(0, int(cx) - reach), min(size, int(cx) + reach + 1)):
                    if (x - cx) ** 2 + (y - cy) ** 2 <= radius2:
                        weight = image[y0 + y, x0 + x] - floor
                        if weight > 0:
                            total += weight
                            sx += weight * x
                            sy += weight * y
            if total <= 0:
                break
            moved = np.hypot(sx / total - cx, sy / total - cy)
            cx, cy = sx / total, sy / total
            if fixed and moved < FIXED_APERTURE_SETTLED_PX:
                break
        if total <= 0 or abs(cx - half) + radius > half or abs(cy - half) + radius > half:
            continue
        if light_elongation(image, x0 + cx, y0 + cy, 0.5 * half, background,
                            threshold) > max_elongation:
            continue
        variance, top, lever = 0.0, 0.0, 0.0
        for y in range(max(0, int(cy) - reach), min(size, int(cy) + reach + 1)):
            for x in range(max(0, int(cx) - reach), min(size, int(cx) + reach + 1)):
                distance2 = (x - cx) ** 2 + (y - cy) ** 2
                if distance2 <= radius2:
                    raw = float(image[y0 + y, x0 + x])
                    variance += (raw + read_noise * read_noise) * distance2
                    top = max(top, raw)
                    if raw - floor > 0:
                        lever += np.sqrt(distance2)
        centres[k, 0], centres[k, 1] = cx, cy
        step = step_sigma_px(background_step(image[y0:y0 + size, x0:x0 + size], read_noise),
                             lever, total)
        sigmas[k] = np.sqrt(variance / 2 / total**2 + step**2)
        peaks[k] = top
        lights[k] = main
        settled[k] = True
    return centres, sigmas, peaks, lights, settled


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


@njit(cache=True, fastmath=True)
def continues_line(rows: np.ndarray, x: np.ndarray, sample: int, first: int, last: int,
                   gap_rows: float, off_px: float) -> bool:
    """Whether line sample `sample` (its row and centre column in `rows`, `x`) continues the
    samples `first` to `last`: within `gap_rows` rows of the nearer end of them, and within
    `off_px` of the least-squares straight line (column against row) through them."""
    nearest = first if abs(rows[first] - rows[sample]) < abs(rows[last] - rows[sample]) \
        else last
    if abs(rows[sample] - rows[nearest]) > gap_rows:
        return False
    count = last - first + 1
    mean_row = 0.0
    mean_x = 0.0
    for k in range(first, last + 1):
        mean_row += rows[k] / count
        mean_x += x[k] / count
    covariance = 0.0
    variance = 0.0
    for k in range(first, last + 1):
        covariance += (rows[k] - mean_row) * (x[k] - mean_x)
        variance += (rows[k] - mean_row) ** 2
    slope = covariance / variance if variance > 0 else 0.0
    return abs(x[sample] - (mean_x + slope * (rows[sample] - mean_row))) <= off_px


@njit(cache=True, fastmath=True)
def remove_line(window: np.ndarray, background: float, slope: float, intercept: float,
                spot_row: float, reach: int, step_px: float, threshold: float,
                saturation_level: float, first_row: int, last_row: int
                ) -> tuple[np.ndarray, np.ndarray, float, int]:
    """The window's signal with a straight laser line's light taken away.

    The line lies on the window's rows `first_row` to `last_row` (a window can hold the
    line's end); its centre on row y is at column intercept + slope·y; its cross profile
    (signal against the column's offset from that centre, in bins of `step_px`) is the median
    of each bin over the pixels within `reach` of the centre on its rows farther than `reach`
    from `spot_row`, and is subtracted (interpolated) from every pixel of its rows within
    `reach` of the line. Returns what is left (0 on the unknown pixels), the unknown pixels
    (saturated where the line alone is above `threshold`), the line's half width at
    `threshold` [px, along the row], and how many pixels the profile rests on."""
    height, width = window.shape
    bins = 2 * int(np.round(reach / step_px)) + 1
    middle = bins // 2
    bin_of = np.empty(height * width, np.int64)
    value_of = np.empty(height * width)
    count = 0
    for y in range(max(first_row, 0), min(last_row + 1, height)):
        if abs(y - spot_row) <= reach:
            continue
        for x in range(width):
            offset = x - (intercept + slope * y)
            if abs(offset) <= reach:
                bin_of[count] = int(np.round(offset / step_px)) + middle
                value_of[count] = window[y, x] - background
                count += 1
    left = np.zeros((height, width))
    unknown = np.zeros((height, width), np.bool_)
    if count == 0:
        return left, unknown, 0.0, 0
    # Each bin's median (the bins that hold pixels), interpolated across the empty ones.
    order = np.argsort(bin_of[:count], kind="mergesort")
    sorted_bins, sorted_values = bin_of[:count][order], value_of[:count][order]
    known = np.zeros(bins, np.int64)
    medians = np.zeros(bins)
    found, half_width, first = 0, 0.0, 0
    while first < count:
        last = first
        while last < count and sorted_bins[last] == sorted_bins[first]:
            last += 1
        ordered = np.sort(sorted_values[first:last])
        n = last - first
        known[found] = sorted_bins[first]
        medians[found] = 0.5 * (ordered[(n - 1) // 2] + ordered[n // 2])
        if medians[found] > threshold:
            half_width = max(half_width, abs(sorted_bins[first] - middle) * step_px)
        found, first = found + 1, last
    known, medians = known[:found], medians[:found]
    profile = np.interp(np.arange(bins + 1).astype(np.float64), known.astype(np.float64),
                        medians)
    for y in range(height):
        for x in range(width):
            signal = window[y, x] - background
            offset = x - (intercept + slope * y)
            light = 0.0
            if abs(offset) <= reach and first_row <= y <= last_row:
                position = min(max(offset / step_px + middle, 0.0), bins - 1.0)
                lower = int(position)
                light = profile[lower] + (position - lower) * (profile[lower + 1] -
                                                               profile[lower])
            if window[y, x] >= saturation_level and light > threshold:
                unknown[y, x] = True
            else:
                left[y, x] = signal - light
    return left, unknown, half_width, count


@njit(cache=True, fastmath=True)
def symmetry_mismatch(left: np.ndarray, states: np.ndarray, cx: float, cy: float, reach: int,
                      threshold: float, stride: int) -> tuple[float, int]:
    """Mean squared difference between `left` at each pixel within `reach` of (cx, cy)
    (every `stride`-th row and column) that is not UNKNOWN (`states`, `chroma.pixel_states`)
    and at its mirror image about that centre (bilinear, none of its four neighbours
    UNKNOWN), over the pairs where either side is above `threshold`; and the number of such
    pairs. A LOWER_BOUND side (the mirror's if any of its neighbours is one) holds at least
    its light: it differs only where it is the brighter; a pair of two lower bounds tells
    nothing and is left out."""
    height, width = left.shape
    x0, x1 = max(int(np.floor(cx)) - reach, 0), min(int(np.ceil(cx)) + reach + 1, width)
    y0, y1 = max(int(np.floor(cy)) - reach, 0), min(int(np.ceil(cy)) + reach + 1, height)
    total, count = 0.0, 0
    for y in range(y0, y1, stride):
        for x in range(x0, x1, stride):
            if states[y, x] == UNKNOWN or (x - cx) ** 2 + (y - cy) ** 2 > reach * reach:
                continue
            mx, my = 2 * cx - x, 2 * cy - y
            ix, iy = int(np.floor(mx)), int(np.floor(my))
            if ix < 0 or iy < 0 or ix + 1 >= width or iy + 1 >= height:
                continue
            mirror_state = max(states[iy, ix], states[iy, ix + 1], states[iy + 1, ix],
                               states[iy + 1, ix + 1])
            if mirror_state == UNKNOWN or (mirror_state == LOWER_BOUND and
                                           states[y, x] == LOWER_BOUND):
                continue
            fx, fy = mx - ix, my - iy
            mirror = (left[iy, ix] * (1 - fx) * (1 - fy) + left[iy, ix + 1] * fx * (1 - fy)
                      + left[iy + 1, ix] * (1 - fx) * fy + left[iy + 1, ix + 1] * fx * fy)
            if left[y, x] <= threshold and mirror <= threshold:
                continue
            difference = left[y, x] - mirror
            if states[y, x] == LOWER_BOUND:
                difference = max(difference, 0.0)
            elif mirror_state == LOWER_BOUND:
                difference = min(difference, 0.0)
            total += difference**2
            count += 1
    return total / max(count, 1), count


@njit(cache=True, fastmath=True)
def symmetric_centre(left: np.ndarray, states: np.ndarray, start_x: float, start_y: float,
                     reach: int, threshold: float, span_px: int, min_pairs: int
                     ) -> tuple[float, float, float]:
    """The centre [window px] about which `left` is most nearly point-symmetric
    (`symmetry_mismatch`), searched within `span_px` of the start in steps of 2 px, then
    around the best in steps of 1, 1/2, 1/4 and 1/8 px, and a parabola through the last;
    with its mismatch (inf where no centre has `min_pairs`)."""
    best_x, best_y, best = start_x, start_y, np.inf
    step, radius = 2.0, (span_px + 1) // 2
    for _ in range(5):
        # Steps of a pixel or more compare every other pixel (a quarter of the pairs).
        stride = 2 if step >= 1 else 1
        centre_x, centre_y, best = best_x, best_y, np.inf
        for j in range(-radius, radius + 1):
            for i in range(-radius, radius + 1):
                x, y = centre_x + i * step, centre_y + j * step
                mismatch, pairs = symmetry_mismatch(left, states, x, y, reach, threshold,
                                                    stride)
                if pairs * stride * stride >= min_pairs and mismatch < best:
                    best_x, best_y, best = x, y, mismatch
        step, radius = step / 2, 1
    if not np.isfinite(best):
        return best_x, best_y, best
    # A parabola through the finest step's neighbours, along each axis.
    step *= 2
    offsets = np.zeros(2)
    for axis in range(2):
        dx, dy = (step, 0.0) if axis == 0 else (0.0, step)
        below = symmetry_mismatch(left, states, best_x - dx, best_y - dy, reach, threshold,
                                  1)[0]
        above = symmetry_mismatch(left, states, best_x + dx, best_y + dy, reach, threshold,
                                  1)[0]
        curvature = below - 2 * best + above
        if curvature > 0:
            offsets[axis] = min(max(0.5 * step * (below - above) / curvature, -step), step)
    return best_x + offsets[0], best_y + offsets[1], best


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernels now, not on the first frames."""
    image = np.zeros((64, 64), np.uint8)
    spot_windows(image, np.zeros((1, 2), np.int64), 24, np.ones((49, 49)), 30.0, 0.3, 1.6,
                 0.15, 2.0, 3.0, np.zeros(1))
    background_step(image, 2.0)
    light_elongation(image, 32.0, 32.0, 12.0, 0.0, 30.0)
    line_rows(image, np.zeros(1, np.int64), np.zeros(1, np.int64), 61, 6, 10, 0.15, 30.0, 2.0)
    symmetric_centre(np.zeros((9, 9)), np.zeros((9, 9), np.uint8), 4.0, 4.0, 3, 30.0, 1, 1)
    remove_line(np.zeros((49, 49), np.float32), 0.0, 0.0, 24.0, 24.0, 12, 0.25, 30.0, 250.0,
                0, 48)
    continues_line(np.arange(3.0), np.zeros(3), 2, 0, 1, 8.0, 2.0)
    speckle_sigmas_px(image, np.full((1, 2), 32.0), np.full(1, 12.0), np.full(1, 24), 2.0,
                      250.0, 0.95, np.full(1, np.nan))
    clipped_speckle_sigmas_px(image, np.full((1, 2), 32.0), np.full(1, 6.0), np.full(1, 30.0),
                              2.0, 250.0, 0.95)


@njit(cache=True, fastmath=True)
def opposite_light(image: np.ndarray, cx: float, cy: float, x: int, y: int, read2: float,
                   saturation: float) -> tuple[bool, float, float, bool]:
    """The light at the point opposite image pixel (`x`, `y`) about (`cx`, `cy`), bilinear
    between its four pixels (as differences, so that four equal pixels give their light
    exactly: a saturated plateau is symmetric to the last bit): whether they lie in the
    image, the light, the variance shot and read noise (`read2`, squared) give it (one grey
    level per electron, none from a pixel at or above `saturation`), and whether one of them
    is saturated."""
    height, width = image.shape
    ox, oy = 2 * cx - x, 2 * cy - y
    left, top = int(np.floor(ox)), int(np.floor(oy))
    if left < 0 or top < 0 or left + 1 >= width or top + 1 >= height:
        return False, 0.0, 0.0, False
    tx, ty = ox - left, oy - top
    corners = (float(image[top, left]), float(image[top, left + 1]),
               float(image[top + 1, left]), float(image[top + 1, left + 1]))
    upper = corners[0] + tx * (corners[1] - corners[0])
    lower = corners[2] + tx * (corners[3] - corners[2])
    light = upper + ty * (lower - upper)
    shares = ((1 - tx) * (1 - ty), tx * (1 - ty), (1 - tx) * ty, tx * ty)
    variance, saturated = 0.0, False
    for k in range(4):
        if corners[k] < saturation:
            variance += shares[k] ** 2 * (max(corners[k], 0.0) + read2)
        else:
            saturated = True
    return True, light, variance, saturated


@njit(cache=True, fastmath=True)
def speckle_light(image: np.ndarray, cx: float, cy: float, radius: float, floor: float,
                  read_noise: float, saturation: float, weight_floor: float
                  ) -> tuple[int, int, float, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                             np.ndarray]:
    """A spot's light within `radius` of (`cx`, `cy`) [image px], as the speckle estimates
    read it: its top-left corner (`x0`, `y0`) of a box, the centroid's weight W (all the
    light above `weight_floor` in the aperture: `floor` for a fixed aperture's centroid, the
    clipped level for a still's), and per pixel of the box (0 outside the aperture, off the
    image, and where the pixel or its opposite is saturated, at or above `saturation`: no
    fluctuation is seen there):

    - odd: half the pixel's difference from the light at the opposite point (bilinear).
      Only the odd part of a spot's light moves its centroid.
    - white: the odd part's variance from shot and read noise alone (the pixel's and the
      four interpolated ones', one grey level per electron as the photon σ counts it).
    - even: the light above `floor` the speckle multiplies: the mean of the pixel and its
      opposite, less `floor`, at least 0.
    - weighed: `even` where the pixel is above `weight_floor` (the centroid weighs it, and
      the speckle on all of its light above `floor` moves it), else 0.
    - usable: the pixels that tell the speckle (`speckle_sums`): on rings (1 px wide about
      the centre) whose mean light is within a third of saturation and none of whose
      pixels is saturated. A ring, not each pixel by its own light: choosing dark pixels
      would choose dark grains (hiding the speckle's variance); a grain three times its
      mean is rare (2 % at a contrast of 0.7), so such a ring's light is seen whatever its
      speckle.
    """
    reach = int(np.ceil(radius)) + 1
    x0, y0 = int(np.floor(cx)) - reach, int(np.floor(cy)) - reach
    size = 2 * reach + 2
    rings = reach + 1
    odd = np.zeros((size, size))
    white = np.zeros((size, size))
    even = np.zeros((size, size))
    weighed = np.zeros((size, size))
    seen = np.zeros((size, size), np.bool_)
    total, count = np.zeros(rings), np.zeros(rings)
    tainted = np.zeros(rings, np.bool_)
    weight_total = 0.0
    height, width = image.shape
    read2 = read_noise * read_noise
    for j in range(size):
        for i in range(size):
            x, y = x0 + i, y0 + j
            distance = np.sqrt((x - cx) ** 2 + (y - cy) ** 2)
            if distance > radius:
                continue
            ring = int(distance)
            inside, opposite, variance, saturated = opposite_light(image, cx, cy, x, y, read2,
                                                                  saturation)
            if not inside or x < 0 or y < 0 or x >= width or y >= height:
                tainted[ring] = True
                continue
            here = float(image[y, x])
            weight_total += max(here - weight_floor, 0.0)
            if here >= saturation or saturated:
                tainted[ring] = True
                continue
            variance += max(here, 0.0) + read2
            seen[j, i] = True
            odd[j, i] = (here - opposite) / 2
            even[j, i] = max((here + opposite) / 2 - floor, 0.0)
            if here > weight_floor:
                weighed[j, i] = even[j, i]
            white[j, i] = variance / 4
            total[ring] += (here + opposite) / 2 - floor
            count[ring] += 1
    mean = total / np.maximum(count, 1.0)
    usable = np.zeros((size, size), np.bool_)
    for j in range(size):
        for i in range(size):
            if seen[j, i]:
                ring = int(np.sqrt((x0 + i - cx) ** 2 + (y0 + j - cy) ** 2))
                usable[j, i] = not tainted[ring] and mean[ring] > 0 and \
                    mean[ring] + floor < saturation / 3
    return x0, y0, weight_total, odd, white, even, weighed, usable


@njit(cache=True, fastmath=True)
def speckle_sums(x0: int, y0: int, cx: float, cy: float, odd: np.ndarray, white: np.ndarray,
                 even: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """What one spot's light (`speckle_light` about (`cx`, `cy`)) says of the
    multiplicative noise on it (laser speckle: light s·(1 + C·n), n of unit variance,
    correlated ρ₁ between neighbouring pixels). Sums over its usable pixels and their right
    and lower neighbours, each weighted by its squared distance from the centre (the weight
    with which it moves a centroid): [excess, squares, lag excess, lag squares] of
    2·(odd² − white), s², 2·odd·odd' and s·s'. excess / squares estimates C², lag excess /
    lag squares C²·ρ₁: about the truth, C² times the share of the odd part's variance a
    bilinear opposite keeps; about a centre measured from the same light, less (the centre
    takes in some of the odd light)."""
    sums = np.zeros(4)
    size = odd.shape[0]
    for j in range(size):
        for i in range(size):
            if not usable[j, i]:
                continue
            lever = (x0 + i - cx) ** 2 + (y0 + j - cy) ** 2
            sums[0] += lever * 2 * (odd[j, i] ** 2 - white[j, i])
            sums[1] += lever * even[j, i] ** 2
            if i + 1 < size and usable[j, i + 1]:
                sums[2] += lever * 2 * odd[j, i] * odd[j, i + 1]
                sums[3] += lever * even[j, i] * even[j, i + 1]
            if j + 1 < size and usable[j + 1, i]:
                sums[2] += lever * 2 * odd[j, i] * odd[j + 1, i]
                sums[3] += lever * even[j, i] * even[j + 1, i]
    return sums


@njit(cache=True, fastmath=True)
def speckle_sigma_px(x0: int, y0: int, cx: float, cy: float, weight_total: float,
                     even: np.ndarray, contrast2: float, correlation_px: float) -> float:
    """The σ [px] per axis that multiplicative noise of squared contrast `contrast2`,
    correlated between pixels as a Gaussian of σ `correlation_px`, gives the centroid of a
    spot's light (`speckle_light` about (`cx`, `cy`): its `even` part and the centroid's
    weight W): the square root of C²·Σᵢⱼ dᵢ·dⱼ·sᵢ·sⱼ·ρ(i − j) / W², d a pixel's offset from
    the centre along an axis, the mean of the two axes. The correlation is applied
    separably to the fields u = d·s: Σ u·(ρ*u)."""
    if weight_total <= 0 or contrast2 <= 0:
        return 0.0
    size = even.shape[0]
    reach = min(int(np.ceil(3 * correlation_px)), size - 1) if correlation_px > 0 else 0
    taps = np.exp(-np.arange(-reach, reach + 1) ** 2 / (2 * max(correlation_px, 1e-9) ** 2))
    # Padded by `reach` on every side, so each tap's pass runs over whole rows.
    padded = np.zeros((size + 2 * reach, size + 2 * reach))
    rows = np.zeros((size + 2 * reach, size))
    column = np.zeros(size)
    quadratic = 0.0
    for axis in range(2):
        for j in range(size):
            for i in range(size):
                offset = x0 + i - cx if axis == 0 else y0 + j - cy
                padded[j + reach, i + reach] = offset * even[j, i]
        rows[:] = 0.0
        for j in range(size):
            source, target = padded[j + reach], rows[j + reach]
            for t in range(2 * reach + 1):
                tap = taps[t]
                for i in range(size):
                    target[i] += tap * source[i + t]
        for j in range(size):
            column[:] = 0.0
            for t in range(2 * reach + 1):
                tap, row = taps[t], rows[j + t]
                for i in range(size):
                    column[i] += tap * row[i]
            inner = padded[j + reach]
            for i in range(size):
                quadratic += inner[i + reach] * column[i]
    return float(np.sqrt(max(contrast2 * quadratic / 2, 0.0)) / weight_total)


@njit(cache=True)   # NaN marks a spot too near the edge: no fastmath
def speckle_sigmas_px(image: np.ndarray, centres: np.ndarray, radii: np.ndarray,
                      rings: np.ndarray, read_noise: float, saturation: float,
                      max_correlation: float, weight_floors: np.ndarray) -> np.ndarray:
    """Per spot measured in an aperture (`centres` N×2 image px, `radii` px), the σ [px]
    laser speckle gives its centroid (`speckle_sigma_px`): the light above the median of
    the square of half size `rings` about it, where the pixel is above the spot's
    `weight_floors` (NaN: all of it, as a fixed aperture's centroid takes it; a still's
    clipped centroid weighs only the pixels above its clipped level). The speckle's squared
    contrast and its correlation between neighbouring pixels are the
    optics', the same for every spot: the medians over the spots of what each one's light
    says (`speckle_sums`), the correlation at most `max_correlation`. 0 where the spots show
    no speckle, NaN for a spot too near the image's edge."""
    count = centres.shape[0]
    sums = np.zeros((count, 4))
    floors = np.full(count, np.nan)
    corners = np.zeros((count, 2), np.int64)
    weight_totals = np.zeros(count)
    size = 2 * (int(np.ceil(radii.max())) + 1) + 2 if count else 0
    evens = np.zeros((count, size, size))
    height, width = image.shape
    for k in range(count):
        x, y, half = int(np.round(centres[k, 0])), int(np.round(centres[k, 1])), rings[k]
        if x - half < 0 or y - half < 0 or x + half >= width or y + half >= height:
            continue
        floors[k] = ring_median(image[y - half:y + half + 1, x - half:x + half + 1], half,
                                half)
        clipped = not np.isnan(weight_floors[k])
        x0, y0, weight_totals[k], odd, white, even, weighed, usable = speckle_light(
            image, centres[k, 0], centres[k, 1], radii[k], floors[k], read_noise, saturation,
            weight_floors[k] if clipped else floors[k])
        corners[k, 0], corners[k, 1] = x0, y0
        lever_light = weighed if clipped else even
        evens[k, :even.shape[0], :even.shape[1]] = lever_light
        sums[k] = speckle_sums(x0, y0, centres[k, 0], centres[k, 1], odd, white, even, usable)
    sigmas = np.where(np.isfinite(floors), 0.0, np.nan)
    usable_spots = np.isfinite(floors) & (sums[:, 1] > 0) & (sums[:, 3] > 0)
    if not usable_spots.any():
        return sigmas
    contrast2 = np.median(sums[usable_spots, 0] / sums[usable_spots, 1])
    if contrast2 <= 0:
        return sigmas
    neighbours = min(max(np.median(sums[usable_spots, 2] / sums[usable_spots, 3]) /
                         contrast2, 0.0), max_correlation)
    correlation_px = np.sqrt(-0.5 / np.log(neighbours)) if neighbours > 0 else 0.0
    for k in range(count):
        if np.isfinite(floors[k]):
            sigmas[k] = speckle_sigma_px(corners[k, 0], corners[k, 1], centres[k, 0],
                                         centres[k, 1], weight_totals[k], evens[k], contrast2,
                                         correlation_px)
    return sigmas


@njit(cache=True, fastmath=True)
def clipped_odd_weights(image: np.ndarray, cx: float, cy: float, radius: float,
                        weight_floor: float, read_noise: float, saturation: float
                        ) -> tuple[int, int, float, np.ndarray, np.ndarray, np.ndarray]:
    """A still's clipped centroid's weights (the light above `weight_floor` within `radius`
    of (`cx`, `cy`) [image px]) as their speckle σ reads them: the top-left corner (`x0`,
    `y0`) of a box, W (the weights' sum), and per pixel of the box:

    - odd: half the pixel's weight less the weight at the opposite point (bilinear), where
      either weighs; saturated pixels included: laser speckle moves a saturated spot's
      plateau's edge, and on a spot much brighter than saturation that is all it moves.
    - white: the variance shot and read noise alone give `odd` (a saturated pixel none), 0
      where neither weighs.
    - ring: the pixel's 1-px ring about the centre; −1 outside the aperture, off the image
      or where the opposite point is.
    """
    reach = int(np.ceil(radius)) + 1
    x0, y0 = int(np.floor(cx)) - reach, int(np.floor(cy)) - reach
    size = 2 * reach + 2
    odd = np.zeros((size, size))
    white = np.zeros((size, size))
    ring = np.full((size, size), -1, np.int64)
    weight_total = 0.0
    height, width = image.shape
    read2 = read_noise * read_noise
    for j in range(size):
        for i in range(size):
            x, y = x0 + i, y0 + j
            distance = np.sqrt((x - cx) ** 2 + (y - cy) ** 2)
            if distance > radius or x < 0 or y < 0 or x >= width or y >= height:
                continue
            here = float(image[y, x])
            weight = max(here - weight_floor, 0.0)
            weight_total += weight
            inside, opposite, variance, _ = opposite_light(image, cx, cy, x, y, read2,
                                                           saturation)
            if not inside:
                continue
            ring[j, i] = int(distance)
            if here < saturation:
                variance += max(here, 0.0) + read2
            opposite_weight = max(opposite - weight_floor, 0.0)
            if weight > 0 or opposite_weight > 0:
                odd[j, i] = (weight - opposite_weight) / 2
                white[j, i] = variance / 4
    return x0, y0, weight_total, odd, white, ring


@njit(cache=True, fastmath=True)
def clipped_speckle_sums(odd: np.ndarray, white: np.ndarray, ring: np.ndarray) -> np.ndarray:
    """What a clipped centroid's weights (`clipped_odd_weights`) say of the correlation of
    their noise between neighbouring pixels: [lag, variance] sums over the pixels where they
    or their opposites weigh and those pixels' right and lower neighbours, 2·odd·odd' (the
    mean of the two directions) and 2·(odd² − white); lag / variance estimates the
    correlation."""
    sums = np.zeros(2)
    size = odd.shape[0]
    for j in range(size):
        for i in range(size):
            if ring[j, i] < 0 or (white[j, i] <= 0 and odd[j, i] == 0):
                continue
            sums[1] += 2 * (odd[j, i] ** 2 - white[j, i])
            if i + 1 < size and ring[j, i + 1] >= 0:
                sums[0] += odd[j, i] * odd[j, i + 1]
            if j + 1 < size and ring[j + 1, i] >= 0:
                sums[0] += odd[j, i] * odd[j + 1, i]
    return sums


@njit(cache=True, fastmath=True)
def clipped_speckle_sigma_px(x0: int, y0: int, cx: float, cy: float, weight_total: float,
                             odd: np.ndarray, white: np.ndarray, ring: np.ndarray,
                             correlation_px: float) -> float:
    """The σ [px] per axis the noise its odd part shows (`clipped_odd_weights`) gives a
    clipped centroid: each pixel's weight varies by the mean over its ring of
    2·(odd² − white), at least 0 (a ring, not the pixel: one pixel's odd part is one draw),
    correlated between pixels as a Gaussian of σ `correlation_px`: `speckle_sigma_px` with
    the square root of that variance as the light and a squared contrast of 1."""
    size = odd.shape[0]
    rings = ring.max() + 1
    total, count = np.zeros(max(rings, 1)), np.zeros(max(rings, 1))
    for j in range(size):
        for i in range(size):
            if ring[j, i] >= 0:
                total[ring[j, i]] += 2 * (odd[j, i] ** 2 - white[j, i])
                count[ring[j, i]] += 1
    spread = np.zeros((size, size))
    for j in range(size):
        for i in range(size):
            if ring[j, i] >= 0:
                spread[j, i] = np.sqrt(max(total[ring[j, i]] / count[ring[j, i]], 0.0))
    return speckle_sigma_px(x0, y0, cx, cy, weight_total, spread, 1.0, correlation_px)


@njit(cache=True)   # NaN marks a spot too near the edge: no fastmath
def clipped_speckle_sigmas_px(image: np.ndarray, centres: np.ndarray, radii: np.ndarray,
                              weight_floors: np.ndarray, read_noise: float, saturation: float,
                              max_correlation: float) -> np.ndarray:
    """Per spot measured by a still's clipped centroid (`centres` N×2 image px, `radii` its
    aperture px, `weight_floors` the level its weights start at), the σ [px] laser speckle
    gives it (`clipped_speckle_sigma_px`), from the noise the odd part of its own weights
    shows beyond shot and read noise, saturated pixels included: a spot brighter than
    saturation shows its speckle only as a ragged plateau edge, and its wings are mostly
    its bloom, which shows none. The noise's correlation between neighbouring pixels is the
    optics': the median over the spots of what each one's weights say
    (`clipped_speckle_sums`), at most `max_correlation`. NaN for a spot too near the
    image's edge."""
    count = centres.shape[0]
    height, width = image.shape
    sigmas = np.full(count, np.nan)
    ratios = np.full(count, np.nan)
    size = 2 * (int(np.ceil(radii.max())) + 1) + 2 if count else 0
    corners = np.zeros((count, 2), np.int64)
    sizes = np.zeros(count, np.int64)
    weight_totals = np.zeros(count)
    odds, whites = np.zeros((count, size, size)), np.zeros((count, size, size))
    rings = np.full((count, size, size), -1, np.int64)
    for k in range(count):
        reach = int(np.ceil(radii[k])) + 1
        x, y = int(np.floor(centres[k, 0])), int(np.floor(centres[k, 1]))
        if x - reach < 0 or y - reach < 0 or x + reach + 1 >= width or \
                y + reach + 1 >= height:
            continue
        sigmas[k] = 0.0
        corners[k, 0], corners[k, 1], weight_totals[k], odd, white, ring = \
            clipped_odd_weights(image, centres[k, 0], centres[k, 1], radii[k],
                                weight_floors[k], read_noise, saturation)
        sizes[k] = odd.shape[0]
        odds[k, :sizes[k], :sizes[k]] = odd
        whites[k, :sizes[k], :sizes[k]] = white
        rings[k, :sizes[k], :sizes[k]] = ring
        sums = clipped_speckle_sums(odd, white, ring)
        if sums[1] > 0:
            ratios[k] = sums[0] / sums[1]
    measured = np.isfinite(ratios)
    if not measured.any():
        return sigmas
    neighbours = min(max(np.median(ratios[measured]), 0.0), max_correlation)
    correlation_px = np.sqrt(-0.5 / np.log(neighbours)) if neighbours > 0 else 0.0
    for k in range(count):
        if np.isfinite(sigmas[k]) and weight_totals[k] > 0:
            box = sizes[k]
            sigmas[k] = clipped_speckle_sigma_px(
                corners[k, 0], corners[k, 1], centres[k, 0], centres[k, 1], weight_totals[k],
                odds[k, :box, :box], whites[k, :box, :box], rings[k, :box, :box],
                correlation_px)
    return sigmas
    neighbours = min(max(np.median(ratios[measured]), 0.0), max_correlation)
    correlation_px = np.sqrt(-0.5 / np.log(neighbours)) if neighbours > 0 else 0.0
    for k in range(count):
        if np.isfinite(sigmas[k]):
            x0, y0, weight_total, odd, white, ring = clipped_odd_weights(
                image, centres[k, 0], centres[k, 1], radii[k], weight_floors[k], read_noise,
                saturation)
            if weight_total > 0:
                sigmas[k] = clipped_speckle_sigma_px(x0, y0, centres[k, 0], centres[k, 1],
                                                     weight_total, odd, white, ring,
                                                     correlation_px)
    return sigmas
