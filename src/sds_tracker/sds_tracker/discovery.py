"""Every laser-like spot in a region, found without any beam's path (calibration frames).

The tracker confines each spot to its beam's image path; a rig whose beams and camera pose
are not yet known has no trustworthy paths, so calibration starts here: all compact blobs
above the local background are candidates (spots and wall reflections alike, seed Fig. 9a),
each measured with the tracker's own centroid. Which candidate belongs to which diode is
decided later, geometrically (sds_recon.calibration.identification).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from sds_tracker.spots import LOST, SpotSettings, SpotTracker, line_free_centre

BACKGROUND_SCALE = 4
"""The background is estimated on the region shrunk by this factor (cheap, spots vanish)."""
BACKGROUND_KERNEL_PX = 9
"""Opening kernel at the shrunk scale: wider than any spot, narrower than the rim's bends."""
BESIDE_LINE_SIGMA_PX = 1.2
"""Least uncertainty of a spot measured on or beside the laser line (the line's light taken
away or left out symmetrically). Measured against the truth on six random rigs' one-axis tilt
series: 78 such spots, error RMS 1.22 px (p90 1.8, max 4.1; a diode under the line keeps its
bias in every frame), where the other 882 spots have 0.058 px. Taken as 0.5 px, such spots
moved a beam by up to 12 times its stated σ in the two-axis protocol."""


@dataclass(frozen=True)
class SpotCandidates:
    """Blobs found in one frame: full-frame centroid (N×2 px), σ [px], raw peak."""

    pixels: np.ndarray
    sigma_px: np.ndarray
    peak: np.ndarray

    def __len__(self) -> int:
        return len(self.pixels)


def find_spots(red: np.ndarray, offset: tuple[int, int] = (0, 0),
               settings: SpotSettings | None = None, min_area_px: int = 3,
               max_area_px: int = 5000,
               line: tuple[np.ndarray, np.ndarray] | None = None) -> SpotCandidates:
    """All compact blobs `settings.threshold` above the local background in `red` (the red
    channel of the region at `offset`, x, y), each measured as the tracker measures a spot.

    With `line`, the laser line's full-frame rows and columns in this image, a spot the line
    passes is measured with the line's light subtracted, as the tracker does
    (`sds_tracker.spots.line_free_centre`); without it, with the line's pixels left out
    symmetrically."""
    s = settings or SpotSettings()
    image = np.ascontiguousarray(red)
    small = cv2.resize(image, None, fx=1 / BACKGROUND_SCALE, fy=1 / BACKGROUND_SCALE,
                       interpolation=cv2.INTER_AREA)
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (BACKGROUND_KERNEL_PX,) * 2)
    background = cv2.resize(cv2.morphologyEx(small, cv2.MORPH_OPEN, kernel),
                            (image.shape[1], image.shape[0]), interpolation=cv2.INTER_LINEAR)
    mask = (cv2.subtract(image, background) > s.threshold).astype(np.uint8)
    starts, line_mask = _blob_starts(mask, min_area_px, max_area_px)
    starts = starts + np.asarray(offset, dtype=float)
    if len(starts) == 0:
        return SpotCandidates(np.zeros((0, 2)), np.zeros(0), np.zeros(0))
    # The tracker's centroid, with each blob's own start as its prior and path.
    tracker = SpotTracker({k: np.array([p, p]) for k, p in enumerate(starts)},
                          replace(s, path_tolerance_px=1e9))
    for k, start in enumerate(starts):
        tracker.previous[k] = start
    estimates = tracker.update(image, offset)
    found = [k for k, e in enumerate(estimates) if not e.flags & LOST]
    pixels = np.array([[estimates[k].x_px, estimates[k].y_px] for k in found]).reshape(-1, 2)
    sigma = np.array([estimates[k].sigma_px for k in found])
    for row, k in enumerate(found):
        refined = None
        if line is not None and len(line[0]) > 1:
            refined = line_free_centre(image, np.asarray(offset, float), pixels[row], line, s)
        if refined is None:
            refined = _beside_line(image, np.asarray(offset, float), pixels[row], line_mask, s,
                                   estimates[k].peak)
        if refined is not None:
            pixels[row] = refined
            sigma[row] = max(sigma[row], BESIDE_LINE_SIGMA_PX)
    # Two starts on one blob settle on the same centroid: keep one.
    unique = _first_of_duplicates(pixels, tolerance_px=1.0)
    return SpotCandidates(pixels[unique], sigma[unique],
                          np.array([estimates[k].peak for k in found])[unique])


def _blob_starts(mask: np.ndarray, min_area_px: int, max_area_px: int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Centroids (N×2, region px) of the compact blobs in a mask, and of the spots sitting on
    thin structures (the laser line): those are opened away with a disk wider than the
    structure, which the fatter spots survive. Also the mask of the thin structures alone."""
    count, labels, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
    starts = []
    thin = np.zeros_like(mask)
    for label in range(1, count):
        x, y, w, h, area = stats[label]
        length = max(w, h)
        width = area / length
        if min_area_px <= area <= max_area_px and length <= 4 * width:
            starts.append(centroids[label])
            continue
        if area < min_area_px or length <= 4 * width:
            continue
        size = 2 * int(np.ceil(0.75 * width)) + 1
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
        crop = (labels[y:y + h, x:x + w] == label).astype(np.uint8)
        opened = cv2.morphologyEx(crop, cv2.MORPH_OPEN, kernel)
        thin[y:y + h, x:x + w] |= crop & (1 - opened)
        inner, _, inner_stats, inner_centroids = cv2.connectedComponentsWithStats(opened)
        starts += [inner_centroids[k] + (x, y) for k in range(1, inner)
                   if inner_stats[k, cv2.CC_STAT_AREA] >= min_area_px]
    thin = cv2.dilate(thin, np.ones((3, 3), np.uint8))
    return np.array(starts, dtype=float).reshape(-1, 2), thin.astype(bool)


def _beside_line(image: np.ndarray, offset: np.ndarray, centre: np.ndarray,
                 line_mask: np.ndarray, s: SpotSettings, peak: float,
                 iterations: int = 8) -> np.ndarray | None:
    """The spot-core centroid with the line's pixels left out, and their mirror images about
    the centre too, so that the spot's own symmetry keeps the centroid unbiased. Spots with no
    line pixel nearby come back unchanged."""
    half = s.window_px
    cx, cy = np.round(centre - offset).astype(int)
    x0, y0, x1, y1 = cx - half, cy - half, cx + half + 1, cy + half + 1
    if x0 < 0 or y0 < 0 or x1 > image.shape[1] or y1 > image.shape[0]:
        return None
    near_line = _line_band(line_mask[y0:y1, x0:x1], centre - offset - (x0, y0),
                           0.75 * s.window_px)
    if not near_line.any():
        return None
    raw = image[y0:y1, x0:x1].astype(np.float32)
    border = np.concatenate([raw[0], raw[-1], raw[:, 0], raw[:, -1]])
    background = float(np.median(border))
    weights = np.clip(raw - background - s.clip_fraction * (peak - background), 0, None)
    ys, xs = np.mgrid[y0:y1, x0:x1].astype(float)
    xs, ys = xs + offset[0], ys + offset[1]
    local = centre - offset - (x0, y0)
    for _ in range(iterations):
        mirror_x = np.round(2 * local[0] - (xs - offset[0] - x0)).astype(int)
        mirror_y = np.round(2 * local[1] - (ys - offset[1] - y0)).astype(int)
        inside = (mirror_x >= 0) & (mirror_x < near_line.shape[1]) & (mirror_y >= 0) & \
            (mirror_y < near_line.shape[0])
        mirrored = np.ones_like(near_line)
        mirrored[inside] = near_line[mirror_y[inside], mirror_x[inside]]
        use = weights * ~(near_line | mirrored)
        total = float(use.sum())
        if total <= 0:
            return None
        centre = np.array([np.sum(use * xs), np.sum(use * ys)]) / total
        local = centre - offset - (x0, y0)
    return centre


def _line_band(thin: np.ndarray, spot: np.ndarray, spot_radius_px: float) -> np.ndarray:
    """The straight band that the thin pixels of a window make away from the spot, continued
    across the whole window (under the spot the line is hidden in the spot's own blob)."""
    ys, xs = np.nonzero(thin)
    points = np.column_stack([xs, ys]).astype(float)
    points = points[np.linalg.norm(points - spot, axis=1) > spot_radius_px]
    if len(points) < 5:
        return np.zeros_like(thin)
    middle = points.mean(axis=0)
    along = np.linalg.eigh(np.cov((points - middle).T))[1][:, -1]
    across = np.array([-along[1], along[0]])
    half_width = float(np.percentile(np.abs((points - middle) @ across), 95)) + 1.0
    grid_y, grid_x = np.mgrid[0:thin.shape[0], 0:thin.shape[1]]
    distance = np.abs((grid_x - middle[0]) * across[0] + (grid_y - middle[1]) * across[1])
    return distance <= half_width


def _first_of_duplicates(pixels: np.ndarray, tolerance_px: float) -> list[int]:
    """Indices of the points that have no earlier point within `tolerance_px`."""
    kept: list[int] = []
    for k, point in enumerate(pixels):
        if all(np.hypot(*(point - pixels[j])) > tolerance_px for j in kept):
            kept.append(k)
    return kept
