"""How far a video's spot σ falls short of the spots' scatter on a surface at rest.

A spot a video measures in its fixed aperture, clear of the laser line, states its own σ from
its light: photons, read noise and the speckle that light shows
(`SpotTracker.measures_own_speckle`). How much speckle a saturated, blooming spot really
carries is hard to read from one frame, and the σ can fall short of it. The repeated frames of
each still of a calibration from the camera's own video (the liquid at rest, new speckle in
every frame, the video's codec as in the drop) show it: their spots' scatter from frame to
frame against their stated σ gives one factor for the rig and its camera settings
(`spot_sigma_scale` in the calibrated rig's record), which the tracker applies to those
spots' σ (`FrameTracker`).
"""

from __future__ import annotations

import numpy as np
from sds_model.rig import Rig

from sds_tracker.spots import is_measured
from sds_tracker.tracker import FrameTracker

MIN_FRAMES = 3
"""Frames a diode's spot must be measured in, in one still, for its scatter to count."""


def video_sigma_scale(rig: Rig, stills: list[list[np.ndarray]], offset: tuple[int, int]
                      ) -> float | None:
    """The factor (≥ 1) by which the σ of a video's spots that measure their own speckle must
    grow to hold their scatter over each still's frames (red channel of the region at
    `offset`, tracked as a video with `rig`): √(mean over spots of scatter / mean σ², per
    axis), with their σ before any scale `rig`'s record holds; 1 where that is below 1; None
    where no spot was measured in MIN_FRAMES frames of a still. Never below 1: the camera's
    codec copies a still scene from frame to frame, so its errors there stay put and their
    scatter understates those of a moving surface."""
    ratios = []
    for frames in stills:
        if len(frames) < MIN_FRAMES:
            continue
        tracker = FrameTracker(rig)
        seen: dict[int, list[tuple[float, float, float]]] = {}
        for red in frames:
            estimates, _ = tracker.measure(red, offset)
            for estimate in estimates:
                if is_measured(estimate.flags) and tracker.spots.measures_own_speckle(estimate):
                    seen.setdefault(estimate.laser_id, []).append(
                        (estimate.x_px, estimate.y_px, estimate.sigma_px / tracker.sigma_scale))
        for rows in seen.values():
            if len(rows) >= MIN_FRAMES:
                spot = np.array(rows)
                scatter_px2 = float(np.sum(np.var(spot[:, :2], axis=0, ddof=1))) / 2
                ratios.append(scatter_px2 / float(np.mean(spot[:, 2] ** 2)))
    if not ratios:
        return None
    return max(1.0, float(np.sqrt(np.mean(ratios))))
