"""A run's own check of its spots' σ: how far they scatter across their beams' image paths.

A diode's spot can only move along its beam's image path (`beam_image_path`): the surface's
height moves it there and nothing else does. So its scatter across the path, about its own
mean offset (which holds the rig file's small error in the path), is its measurement's error
in that direction, and the RMS of that scatter over the spots' own σ says, without any truth,
whether those σ are honest (about 1), too short (above) or too long (below). On development
videos it was within 0.8–1.0 of the truth's error/σ in every imaging case (bench/README,
"a run's own check of its σ"), a little below where part of a spot's error is the same in
every frame (a mean offset takes that in).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from sds_model.rig import Rig
from sds_recon.triangulation import beam_image_path

from sds_tracker.tracker import TrackerConfig, path_heights_mm

MIN_FRAMES = 5
"""A spot counts once it was measured in this many frames (its mean offset then costs little)."""


def across_path_px(path_px: np.ndarray, points_px: np.ndarray) -> np.ndarray:
    """Signed distance [px] of each point (N×2) from a path (M×2 polyline, M ≥ 2): from its
    nearest point on the nearest segment, positive to the left of the path's direction."""
    start, step = path_px[:-1], np.diff(path_px, axis=0)
    length2 = np.maximum(np.einsum("ij,ij->i", step, step), 1e-12)
    offset = points_px[:, None, :] - start[None, :, :]
    along = np.clip(np.einsum("nij,ij->ni", offset, step) / length2, 0.0, 1.0)
    gap = offset - along[..., None] * step[None, :, :]
    distance = np.hypot(gap[..., 0], gap[..., 1])
    nearest = np.argmin(distance, axis=1)
    rows = np.arange(len(points_px))
    chosen, direction = gap[rows, nearest], step[nearest]
    side = np.sign(direction[:, 0] * chosen[:, 1] - direction[:, 1] * chosen[:, 0])
    return np.where(side < 0, -1.0, 1.0) * distance[rows, nearest]


@dataclass(frozen=True)
class SigmaCheck:
    """A run's spots' scatter across their paths over their σ (RMS), from how many spots and
    measurements."""

    scatter_over_sigma: float
    spots: int
    measurements: int

    def line(self) -> str:
        """What a summary says of it."""
        verdict = ("the σ are honest" if 0.8 <= self.scatter_over_sigma <= 1.25 else
                   "the σ are too short" if self.scatter_over_sigma > 1.25 else
                   "the σ are too long")
        return (f"scatter across their beams' paths over their σ: RMS "
                f"{self.scatter_over_sigma:.2f}, {verdict} (about 1 when honest; "
                f"{self.spots} spots, {self.measurements} measurements)")


@dataclass
class PathScatter:
    """Sums per diode of its measured spots' offsets r [px] from its path and their weights
    w = 1/σ², from which `check` gives Σ (r − r̄)²·w over Σ (n − 1), r̄ each diode's mean."""

    paths_px: dict[int, np.ndarray]
    sums: dict[int, np.ndarray] = field(default_factory=dict)   # n, Σr, Σr·w, Σr²·w, Σw

    @classmethod
    def for_rig(cls, rig: Rig) -> PathScatter:
        """Empty sums for the rig's tracked diodes' paths, over the heights the tracker's
        paths span."""
        heights = path_heights_mm(TrackerConfig())
        return cls({d.laser_id: beam_image_path(rig, d.laser_id, heights)
                    for d in rig.tracked_diodes})

    def add(self, laser_ids: np.ndarray, points_px: np.ndarray, sigmas_px: np.ndarray) -> None:
        """A frame's measured spots: their diodes, raw positions (N×2 px) and σ [px]."""
        for laser_id, point, sigma in zip(laser_ids, points_px, sigmas_px, strict=True):
            path = self.paths_px.get(int(laser_id))
            if path is None or not (np.isfinite(point).all() and sigma > 0):
                continue
            offset = float(across_path_px(path, point[None, :])[0])
            weight = 1.0 / float(sigma) ** 2
            sums = self.sums.setdefault(int(laser_id), np.zeros(5))
            sums += (1.0, offset, offset * weight, offset**2 * weight, weight)

    def check(self) -> SigmaCheck | None:
        """The check over the diodes measured in MIN_FRAMES frames or more; None if none was."""
        chi2, dof, spots, measurements = 0.0, 0, 0, 0
        for n, total, weighted, squares, weights in self.sums.values():
            if n < MIN_FRAMES:
                continue
            mean = total / n
            chi2 += squares - 2 * mean * weighted + mean**2 * weights
            dof += int(n) - 1
            spots += 1
            measurements += int(n)
        if not dof:
            return None
        return SigmaCheck(float(np.sqrt(max(chi2, 0.0) / dof)), spots, measurements)
