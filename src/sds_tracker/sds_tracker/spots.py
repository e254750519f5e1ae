"""Laser spots frame by frame (seed Sec. 3.4): windowed centroids confined to each beam's path."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from sds_tracker.kernels import spot_windows

LOST, SATURATED, REFLECTION_SUSPECTED, OFF_PATH, HAMPEL_REPLACED, NOT_FILTERED = 1, 2, 4, 8, 16, 32
"""Flag bits, the same as sds_msgs/LaserSpot's."""
LINE_SIGMA_PX = 0.5
"""Least uncertainty of a spot measured with the laser line's light subtracted (a saturated
spot on the line keeps a bias of about 1.4 px across the line)."""


@dataclass(frozen=True)
class SpotSettings:
    """Tracking parameters (config/params/tracker.yaml documents each)."""

    window_px: int = 24            # half size of the window read around a spot
    prior_sigma_px: float = 8.0    # Gaussian prior on the motion since the previous frame
    threshold: float = 30.0        # signal above the local background that makes a spot
    aperture_factor: float = 1.6   # centroid aperture radius / the blob's radius at threshold
    clip_fraction: float = 0.15    # share of the peak removed before the centroid (see below)
    path_tolerance_px: float = 4.0  # farthest a spot may lie from its beam's image path
    saturation_level: float = 250.0
    read_noise: float = 2.0        # grey levels, for the position uncertainty
    min_competitor: float = 0.3    # a second blob this bright (relative) flags a reflection


@dataclass(frozen=True)
class SpotEstimate:
    """One spot in one frame: full-frame pixel, uncertainty [px], peak, flags."""

    laser_id: int
    x_px: float
    y_px: float
    sigma_px: float
    peak: float
    flags: int


def distance_to_path(point: np.ndarray, path: np.ndarray) -> float:
    """Shortest distance [px] from a point to a polyline."""
    return float(distances_to_paths(point[None], path[None])[0])


def distances_to_paths(points: np.ndarray, paths: np.ndarray) -> np.ndarray:
    """Shortest distance [px] from each point (N×2) to its polyline (N×M×2)."""
    a, b = paths[:, :-1], paths[:, 1:]
    segment = b - a
    length2 = np.maximum(np.sum(segment * segment, axis=2), 1e-12)
    t = np.clip(np.sum((points[:, None] - a) * segment, axis=2) / length2, 0.0, 1.0)
    closest = a + t[..., None] * segment
    return np.min(np.linalg.norm(closest - points[:, None], axis=2), axis=1)


class SpotTracker:
    """Track every diode's spot: acquire it on its path, then follow it in a small window.

    Per spot and frame only a window is read (no full-frame work): background = median of the
    window's border, connected blobs above `threshold`, the blob chosen by brightness times a
    Gaussian prior around the previous position among those within `path_tolerance_px` of the
    beam's path, and the position = intensity centroid of the background-subtracted signal in
    a round aperture (re-centred once). A spot not found is reported lost, with no position,
    and searched for along its whole path in the next frame.
    """

    def __init__(self, paths: dict[int, np.ndarray], settings: SpotSettings | None = None) -> None:
        self.settings = settings or SpotSettings()
        self.paths = {i: np.asarray(p, dtype=float) for i, p in paths.items()}
        self.previous: dict[int, np.ndarray | None] = dict.fromkeys(self.paths)
        # All paths in one array for the batched pass; shorter ones repeat their last point
        # (a zero-length segment, which changes no distance).
        longest = max((len(p) for p in self.paths.values()), default=0)
        self._row = {i: k for k, i in enumerate(self.paths)}
        self._stacked_paths = np.array([np.vstack([p, np.repeat(p[-1:], longest - len(p), 0)])
                                        for p in self.paths.values()])
        half = self.settings.window_px
        yy, xx = np.mgrid[-half:half + 1, -half:half + 1]
        # The previous position is a window's centre (to half a pixel): one prior for all.
        self._prior = np.exp(-(xx**2 + yy**2) / (2 * self.settings.prior_sigma_px**2))

    def update(self, image: np.ndarray, offset: tuple[int, int] = (0, 0),
               line: tuple[np.ndarray, np.ndarray] | None = None) -> list[SpotEstimate]:
        """Estimates for one frame; `image` is the red channel of the region at `offset` (x, y).

        Spots tracked in the previous frame go through one batched pass over all their windows;
        any spot that pass cannot settle (not found, a competing blob, off its path, near the
        image edge) and every spot not yet acquired take the full per-spot search. `line`, the
        laser line's full-frame (rows, columns) in this frame, if given, rescues a spot the
        line's light pulls off its path (`subtract_line_centroid`).
        """
        origin = np.array(offset, dtype=float)
        tracked = [i for i in self.paths if self.previous[i] is not None]
        settled = self._track_batch(image, origin, tracked) if tracked else {}
        estimates = []
        for laser_id, path in self.paths.items():
            estimate = settled.get(laser_id) or self._track(
                image, origin, laser_id, path, line if line is not None and len(line[0]) > 1
                else None)
            self.previous[laser_id] = None if estimate.flags & LOST else \
                np.array([estimate.x_px, estimate.y_px])
            estimates.append(estimate)
        return estimates

    def _track_batch(self, image: np.ndarray, origin: np.ndarray,
                     ids: list[int]) -> dict[int, SpotEstimate]:
        """The steady state, compiled over all spots (kernels.spot_windows): the same centroid
        as `_track` for every spot whose window holds one clear blob near its previous
        position."""
        s = self.settings
        half = s.window_px
        size = 2 * half + 1
        previous = np.array([self.previous[i] for i in ids]) - origin
        corner = np.round(previous).astype(int) - half
        inside = (corner >= 0).all(axis=1) & (corner[:, 0] + size <= image.shape[1]) & \
            (corner[:, 1] + size <= image.shape[0])
        ids = [i for i, ok in zip(ids, inside, strict=True) if ok]
        if not ids:
            return {}
        corner = corner[inside]
        centre, sigma, peak_raw, ok = spot_windows(
            image, corner, half, self._prior, s.threshold, s.min_competitor, s.aperture_factor,
            s.clip_fraction, s.read_noise)
        full = centre + corner + origin
        paths = self._stacked_paths[[self._row[i] for i in ids]]
        ok &= distances_to_paths(full, paths) <= s.path_tolerance_px
        settled = {}
        for k, laser_id in enumerate(ids):
            if not ok[k]:
                continue
            flags = SATURATED if peak_raw[k] >= s.saturation_level else 0
            settled[laser_id] = SpotEstimate(laser_id, float(full[k, 0]), float(full[k, 1]),
                                             float(sigma[k]), float(peak_raw[k]), flags)
        return settled

    def _search_box(self, laser_id: int, path: np.ndarray) -> np.ndarray:
        """(x0, y0, x1, y1) full-frame: around the previous position, or the whole path."""
        half = self.settings.window_px
        previous = self.previous[laser_id]
        if previous is not None:
            return np.array([*(previous - half), *(previous + half)])
        return np.array([*(path.min(axis=0) - half), *(path.max(axis=0) + half)])

    def _track(self, image: np.ndarray, origin: np.ndarray, laser_id: int, path: np.ndarray,
               line: tuple[np.ndarray, np.ndarray] | None = None) -> SpotEstimate:
        s = self.settings
        lost = SpotEstimate(laser_id, np.nan, np.nan, np.nan, 0.0, LOST)
        box = np.round(self._search_box(laser_id, path) - np.tile(origin, 2)).astype(int)
        x0, y0 = max(box[0], 0), max(box[1], 0)
        x1, y1 = min(box[2], image.shape[1] - 1), min(box[3], image.shape[0] - 1)
        if x1 - x0 < 4 or y1 - y0 < 4:
            return lost
        window = image[y0:y1 + 1, x0:x1 + 1].astype(np.float32)
        border = np.concatenate([window[0], window[-1], window[:, 0], window[:, -1]])
        background = float(np.median(border))
        signal = window - background
        count, labels, stats, centroids = cv2.connectedComponentsWithStats(
            (signal > s.threshold).astype(np.uint8), connectivity=8)
        if count < 2:
            return lost
        # Every blob's centre, distance to the path and mass at once (label 0: background).
        centres = centroids[1:] + np.array([x0, y0]) + origin
        off_paths = distances_to_paths(centres, np.broadcast_to(path, (count - 1, *path.shape)))
        masses = np.bincount(labels.ravel(), weights=signal.ravel(), minlength=count)[1:]
        previous = self.previous[laser_id]
        priors = np.ones(count - 1) if previous is None else np.exp(
            -np.sum((centres - previous) ** 2, axis=1) / (2 * s.prior_sigma_px**2))
        near_path = off_paths <= s.path_tolerance_px + 2 * np.sqrt(
            stats[1:, cv2.CC_STAT_AREA] / np.pi)
        candidates = [(bool(off_paths[k] <= s.path_tolerance_px), float(masses[k] * priors[k]),
                       float(masses[k]), k + 1, centres[k]) for k in np.flatnonzero(near_path)]
        if not candidates:
            return lost
        # A blob centred on the path comes first: a long stretch of laser line crossing the
        # path outweighs the spot, but its centroid lies off the path.
        candidates.sort(key=lambda c: (c[0], c[1]), reverse=True)
        on_path, _, mass, label, centre = candidates[0]
        flags = 0
        if any(c[0] == on_path and c[2] >= s.min_competitor * mass for c in candidates[1:]):
            flags |= REFLECTION_SUSPECTED
        radius = max(s.aperture_factor * np.sqrt(stats[label, cv2.CC_STAT_AREA] / np.pi), 3.0)
        peak_signal = float(signal[labels == label].max())
        floor = background + s.clip_fraction * peak_signal
        for _ in range(2):
            region = self._aperture(image, origin, centre, radius, floor)
            if region is None:
                return lost
            xs, ys, weights, raw = region
            total = float(weights.sum())
            if total <= 0:
                return lost
            centre = np.array([np.sum(weights * xs), np.sum(weights * ys)]) / total
        peak = float(raw.max())
        variance = np.clip(raw, 0, None) + s.read_noise**2
        sigma = float(np.sqrt(np.sum(variance * ((xs - centre[0]) ** 2 +
                                                 (ys - centre[1]) ** 2)) / 2) / total)
        if distance_to_path(centre, path) > s.path_tolerance_px:
            # A spot merged with the laser line is pulled off its path: measured again with
            # the line's light subtracted, it is kept if it is then on its path.
            refined = None if line is None else line_free_centre(image, origin, centre, line, s)
            if refined is None or distance_to_path(refined, path) > s.path_tolerance_px:
                return SpotEstimate(laser_id, np.nan, np.nan, np.nan, 0.0, LOST | OFF_PATH)
            centre, sigma = refined, max(sigma, LINE_SIGMA_PX)
        if peak >= s.saturation_level:
            flags |= SATURATED
        return SpotEstimate(laser_id, float(centre[0]), float(centre[1]), sigma, peak, flags)

    @staticmethod
    def _aperture(image: np.ndarray, origin: np.ndarray, centre: np.ndarray, radius: float,
                  background: float
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """Full-frame pixel coordinates, background-subtracted weights and raw values of the
        pixels within `radius` of `centre`; None if the aperture leaves the image."""
        half = int(np.ceil(radius)) + 1
        cx, cy = np.round(centre - origin).astype(int)
        x0, y0, x1, y1 = cx - half, cy - half, cx + half, cy + half
        if x0 < 0 or y0 < 0 or x1 >= image.shape[1] or y1 >= image.shape[0]:
            return None
        raw = image[y0:y1 + 1, x0:x1 + 1].astype(np.float32)
        columns = np.arange(x0, x1 + 1) + origin[0]
        rows = np.arange(y0, y1 + 1) + origin[1]
        inside = (columns[None] - centre[0]) ** 2 + (rows[:, None] - centre[1]) ** 2 <= radius**2
        ys, xs = np.nonzero(inside)
        return (columns[xs], rows[ys], np.clip(raw[inside] - background, 0, None),
                raw[inside])


def line_free_centre(image: np.ndarray, origin: np.ndarray, centre: np.ndarray,
                     line: tuple[np.ndarray, np.ndarray], s: SpotSettings) -> np.ndarray | None:
    """The centroid (full-frame px) of the spot in the window around `centre` after the laser
    line's light is subtracted (`subtract_line_centroid`); None where the line (full-frame
    rows and columns) does not cross the window or the window leaves the image."""
    window = spot_window(image.shape, origin, centre, s.window_px)
    if window is None:
        return None
    x0, y0, x1, y1 = window
    line_x = np.interp(np.arange(y0, y1) + origin[1], line[0], line[1],
                       left=np.nan, right=np.nan) - origin[0] - x0
    if not np.any(np.abs(line_x - s.window_px) <= 1.5 * s.window_px):
        return None
    local = subtract_line_centroid(image[y0:y1, x0:x1].astype(np.float32), line_x,
                                   centre - origin - (x0, y0), s)
    return None if local is None else local + origin + (x0, y0)


def spot_window(shape: tuple[int, ...], offset: np.ndarray, centre: np.ndarray, half: int
                ) -> tuple[int, int, int, int] | None:
    """Region-pixel bounds (x0, y0, x1, y1; end exclusive) of the window of half size `half`
    around a full-frame centre, or None where it would leave the image."""
    cx, cy = np.round(centre - offset).astype(int)
    x0, y0, x1, y1 = cx - half, cy - half, cx + half + 1, cy + half + 1
    if x0 < 0 or y0 < 0 or x1 > shape[1] or y1 > shape[0]:
        return None
    return int(x0), int(y0), int(x1), int(y1)


def subtract_line_centroid(window: np.ndarray, line_x: np.ndarray, spot: np.ndarray,
                           s: SpotSettings, iterations: int = 4) -> np.ndarray | None:
    """A spot's centroid [window px] with the laser line's light taken away; None when the
    line does not reach enough of the window's rows or no spot is left.

    `line_x[r]` is the line's centre column on window row r (NaN where unknown); a straight
    line through it on the rows beyond half a window from the spot is used. The line's
    cross profile (signal against the column's offset from `line_x`, whole pixels) is the
    median over the rows that lie beyond half a window from the spot, and is subtracted from
    every row, the spot's included (but for saturated pixels): a spot on the line keeps its
    own light and loses the line's, a spot beside it no longer leans towards it. Then the
    centroid of what is left above `clip_fraction` of its peak, in a disc of half a window,
    iterated from the brightest 5×5 patch of what is left (a spot beside a bright line, taken
    for one blob with it, can lie more than half a window from `spot`).
    """
    rows, columns = np.indices(window.shape)
    border = np.concatenate([window[0], window[-1], window[:, 0], window[:, -1]])
    signal = window - float(np.median(border))
    reach = s.window_px // 2
    # The line's own centre is pulled towards a spot on its rows: a straight line through
    # its centres on the rows away from the spot stands for it on every row.
    row_index = np.arange(len(line_x))
    usable = np.isfinite(line_x) & (np.abs(row_index - spot[1]) > reach)
    if usable.sum() < 4:
        return None
    slope, intercept = np.polyfit(row_index[usable], line_x[usable], 1)
    offset = np.round(columns - (intercept + slope * rows))
    on_line = np.abs(offset) <= reach
    far_rows = np.abs(rows - spot[1]) > reach
    profile_pixels = on_line & far_rows
    if profile_pixels.sum() < 3 * (2 * reach + 1):
        return None
    bins = (offset[profile_pixels] + reach).astype(int)
    profile = np.zeros(2 * reach + 1)
    for b in range(2 * reach + 1):
        values = signal[profile_pixels][bins == b]
        profile[b] = float(np.median(values)) if len(values) else 0.0
    line_light = np.zeros_like(signal)
    line_light[on_line] = profile[(offset[on_line] + reach).astype(int)]
    # A saturated pixel holds less than spot plus line: nothing of the line is taken from it.
    line_light[window >= s.saturation_level] = 0.0
    left = signal - line_light
    # A 5×5 mean: a compact spot outweighs the few saturated line pixels left standing.
    patch = cv2.blur(left.astype(np.float32), (5, 5))
    row, column = np.unravel_index(int(np.argmax(patch)), patch.shape)
    centre = np.array([column, row], dtype=float)
    for _ in range(iterations):
        inside = (columns - centre[0]) ** 2 + (rows - centre[1]) ** 2 <= reach**2
        peak = float(left[inside].max()) if inside.any() else 0.0
        if peak <= s.threshold:
            return None
        weights = np.where(inside, np.clip(left - s.clip_fraction * peak, 0, None), 0.0)
        total = float(weights.sum())
        if total <= 0:
            return None
        centre = np.array([np.sum(weights * columns), np.sum(weights * rows)]) / total
    return centre
