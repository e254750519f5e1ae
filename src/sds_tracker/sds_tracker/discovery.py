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
from scipy.optimize import brentq

from sds_tracker.chroma import has_chroma_blocks
from sds_tracker.spots import (
    LOST,
    ON_LINE_SIGMA_PX,
    LineFreeSpot,
    SpotSettings,
    SpotTracker,
    line_free_centre,
    line_free_sigma_px,
    spot_window,
    window_without_line,
)

BACKGROUND_SCALE = 4
"""The background is estimated on the region shrunk by this factor (cheap, spots vanish)."""
BACKGROUND_KERNEL_PX = 9
"""Opening kernel at the shrunk scale: wider than any spot, narrower than the rim's bends."""
SAME_SPOT_PX = 1.0
"""Farthest [px] a blob in another frame of the same still may lie from the first frame's to
be the same spot: its frames differ by their speckle and noise (tenths of a pixel), a
neighbouring blob or a reflection lies farther."""
MIN_SCATTER_FRAMES = 3
"""Fewest frames of a spot whose scatter is trusted as its uncertainty."""


@dataclass(frozen=True)
class SpotCandidates:
    """Blobs found in one frame: full-frame centroid (N×2 px), its covariance (N×2×2 px²),
    raw peak; for blobs averaged over a still's frames (`averaged`), their frames' scatter
    and a single frame's own variance (N each, px² per axis; NaN where fewer than
    MIN_SCATTER_FRAMES frames saw one)."""

    pixels: np.ndarray
    covariance_px2: np.ndarray
    peak: np.ndarray
    scatter_px2: np.ndarray | None = None
    frame_variance_px2: np.ndarray | None = None

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
    (`sds_tracker.spots.line_free_centre`); without it, the light of the thin structure
    beside the spot is taken away likewise (`_beside_line`). A spot whose light overlaps the
    line's gets ON_LINE_SIGMA_PX along and across it."""
    s = settings or SpotSettings()
    image = np.ascontiguousarray(red)
    if line is not None and len(line[0]) > 1 and s.chroma_blocks is None:
        s = replace(s, chroma_blocks=has_chroma_blocks(image, np.asarray(offset, float), line,
                                                       s.threshold))
    small = cv2.resize(image, None, fx=1 / BACKGROUND_SCALE, fy=1 / BACKGROUND_SCALE,
                       interpolation=cv2.INTER_AREA)
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (BACKGROUND_KERNEL_PX,) * 2)
    background = cv2.resize(cv2.morphologyEx(small, cv2.MORPH_OPEN, kernel),
                            (image.shape[1], image.shape[0]), interpolation=cv2.INTER_LINEAR)
    mask = (cv2.subtract(image, background) > s.threshold).astype(np.uint8)
    starts, line_mask = _blob_starts(mask, min_area_px, max_area_px)
    starts = starts + np.asarray(offset, dtype=float)
    if len(starts) == 0:
        return SpotCandidates(np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0))
    # The tracker's centroid, with each blob's own start as its prior and path; the starts
    # are compact blobs (thin structures opened away), and the line's light beside one is
    # taken away below, so its shape is no test here.
    tracker = SpotTracker({k: np.array([p, p]) for k, p in enumerate(starts)},
                          replace(s, path_tolerance_px=1e9), exclusive=False,
                          max_elongation=np.inf)
    for k, start in enumerate(starts):
        tracker.previous[k] = start
    estimates = tracker.update(image, offset)
    found = [k for k, e in enumerate(estimates) if not e.flags & LOST]
    pixels = np.array([[estimates[k].x_px, estimates[k].y_px] for k in found]).reshape(-1, 2)
    sigma = np.array([estimates[k].sigma_px for k in found])
    covariance = sigma[:, None, None] ** 2 * np.eye(2)
    for row in range(len(found)):
        refined = None
        if line is not None and len(line[0]) > 1:
            refined = line_free_centre(image, np.asarray(offset, float), pixels[row], line, s)
        if refined is None:
            refined = _beside_line(image, np.asarray(offset, float), pixels[row], line_mask, s)
        if refined is not None:
            pixels[row] = refined.centre
            if refined.clearance_px < 0:
                covariance[row] = _on_line_covariance(refined.along, line_free_sigma_px(
                    max(sigma[row], refined.line_sigma_px), refined))
    # A blob that was the line's light alone is no spot; two starts on one blob settle on
    # the same centre: keep one.
    spots = np.flatnonzero(np.isfinite(pixels).all(axis=1))
    unique = spots[_first_of_duplicates(pixels[spots], tolerance_px=1.0)]
    return SpotCandidates(pixels[unique], covariance[unique],
                          np.array([estimates[k].peak for k in found])[unique])


def averaged(frames: list[SpotCandidates], same_spot_px: float = SAME_SPOT_PX
             ) -> SpotCandidates:
    """The first frame's blobs, each averaged over the frames of the same still (the liquid
    at rest, its speckle and noise new in every frame: seed Sec. 3.3.1 step 3, "a short
    video"): with it, the nearest blob of every other frame within `same_spot_px`.

    A blob seen in n frames is their mean; its covariance is the mean of their own
    covariances over n, widened by the ratio of their scatter to it where that is larger
    (from MIN_SCATTER_FRAMES frames on): what a still's frames say of a spot's error, speckle
    included, beside what its photons say. Its peak is the frames' median."""
    first = frames[0]
    pixels, covariances, peaks, scatters, variances = [], [], [], [], []
    for k, pixel in enumerate(first.pixels):
        seen, own, peak = [pixel], [first.covariance_px2[k]], [first.peak[k]]
        for other in frames[1:]:
            if len(other) == 0:
                continue
            distance = np.linalg.norm(other.pixels - pixel, axis=1)
            nearest = int(np.argmin(distance))
            if distance[nearest] <= same_spot_px:
                seen.append(other.pixels[nearest])
                own.append(other.covariance_px2[nearest])
                peak.append(other.peak[nearest])
        count = len(seen)
        mean_covariance = np.mean(own, axis=0)
        widen, spread, variance = 1.0, np.nan, np.nan
        if count >= MIN_SCATTER_FRAMES:
            scatter = np.cov(np.array(seen).T, ddof=1)
            widen = max(1.0, float(np.trace(scatter) / np.trace(mean_covariance)))
            spread, variance = np.trace(scatter) / 2, np.trace(mean_covariance) / 2
        pixels.append(np.mean(seen, axis=0))
        covariances.append(mean_covariance * widen / count)
        peaks.append(float(np.median(peak)))
        scatters.append(spread)
        variances.append(variance)
    return SpotCandidates(np.array(pixels).reshape(-1, 2),
                          np.array(covariances).reshape(-1, 2, 2), np.array(peaks),
                          np.array(scatters), np.array(variances))


def excess_sigma_px(stills: list[SpotCandidates]) -> float | None:
    """The σ [px, per axis] that, added to a single frame's own σ (photons, read noise, the
    background), makes it honest on the stills' repeated frames (`averaged`): chiefly laser
    speckle, new in every frame on a liquid, which a frame's own light cannot show. The
    least σ ≥ 0 with which the blobs' frame scatter over their variance averages 1 (the
    mean, not each blob's excess: blobs whose σ is already wide, on the laser line, do not
    cancel the others'); None where no still had repeated frames."""
    pairs = [(s.scatter_px2, s.frame_variance_px2) for s in stills
             if s.scatter_px2 is not None and s.frame_variance_px2 is not None]
    if not pairs:
        return None
    scatter = np.concatenate([p[0] for p in pairs])
    variance = np.concatenate([p[1] for p in pairs])
    seen = np.isfinite(scatter) & np.isfinite(variance)
    if not seen.any():
        return None
    scatter, variance = scatter[seen], variance[seen]
    if np.mean(scatter / variance) <= 1.0:
        return 0.0
    return float(brentq(lambda sigma: np.mean(scatter / (variance + sigma**2)) - 1.0,
                        0.0, float(np.sqrt(scatter.max()))))


def _on_line_covariance(along: np.ndarray, sigma_px: float) -> np.ndarray:
    """The covariance [px²] of a spot overlapping the line: ON_LINE_SIGMA_PX along and across
    the line's unit direction `along`, or the spot's own σ where that is larger."""
    across = np.array([along[1], -along[0]])
    sigma_along, sigma_across = (max(sigma_px, floor) for floor in ON_LINE_SIGMA_PX)
    return sigma_along**2 * np.outer(along, along) + sigma_across**2 * np.outer(across, across)


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
                 line_mask: np.ndarray, s: SpotSettings) -> LineFreeSpot | None:
    """The spot measured with the light of the thin structure beside it (the laser line, on
    the liquid or a wall) subtracted, as the tracker subtracts the tracked line
    (`window_without_line`); None for a spot with no such structure nearby, or one that
    runs closer to the rows than to the columns."""
    window = spot_window(image.shape, offset, centre, s.window_px)
    if window is None:
        return None
    x0, y0, x1, y1 = window
    band = _line_band(line_mask[y0:y1, x0:x1], centre - offset - (x0, y0),
                      0.75 * s.window_px)
    if band is None or abs(band[1][1]) < abs(band[1][0]):
        return None
    middle, along = band
    line_x = middle[0] + (np.arange(y1 - y0) - middle[1]) * along[0] / along[1]
    return window_without_line(image, offset, window, line_x, centre, s)


def _line_band(thin: np.ndarray, spot: np.ndarray, spot_radius_px: float
               ) -> tuple[np.ndarray, np.ndarray] | None:
    """The straight band that the thin pixels of a window make away from the spot: a point on
    its centre line and its unit direction; None where too few thin pixels lie away from the
    spot."""
    ys, xs = np.nonzero(thin)
    points = np.column_stack([xs, ys]).astype(float)
    points = points[np.linalg.norm(points - spot, axis=1) > spot_radius_px]
    if len(points) < 5:
        return None
    middle = points.mean(axis=0)
    along = np.linalg.eigh(np.cov((points - middle).T))[1][:, -1]
    return middle, along


def _first_of_duplicates(pixels: np.ndarray, tolerance_px: float) -> list[int]:
    """Indices of the points that have no earlier point within `tolerance_px`."""
    offsets = pixels[:, None, :] - pixels[None, :, :]
    distances = np.hypot(offsets[..., 0], offsets[..., 1])
    kept: list[int] = []
    for k in range(len(pixels)):
        if np.all(distances[k, kept] > tolerance_px):
            kept.append(k)
    return kept
