"""A run's own check of its spots' σ: how far they scatter across their beams' image paths.

A diode's spot can only move along its beam's image path (`beam_paths_px`): the surface's
height moves it there and nothing else does. So its scatter across the path, about its own
mean offset (which holds the rig file's small error in the path), is its measurement's error
in that direction, and the RMS of that scatter over the spots' own σ says, without any truth,
whether those σ are honest (about 1), too short (above) or too long (below). On development
videos it was 0.80–1.0 times the truth's error/σ in every imaging case, on held-out ones
0.75–1.0 (bench/README, "a run's own check of its σ"): a little below it where part of a
spot's error is the same in every frame (a mean offset takes that in).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sds_model.rig import Rig

from sds_tracker.spots import nearest_on_paths
from sds_tracker.tracker import TrackerConfig, beam_paths_px, path_heights_mm

MIN_FRAMES = 5
"""A spot counts once it was measured in this many frames (its mean offset then costs little)."""
HONEST_BAND = (0.65, 1.25)
"""The check's values for which a summary calls the σ honest: issue 45's band for error/σ
(0.8–1.25), its lower edge times 0.8, since the check reads low: 0.80–1.0 times the spots'
error/σ on the development videos, 0.68–0.96 times the heights' on the development runs of
the demo's workflow with calibrated rigs (bench/README, "a run's own check of its σ")."""


def across_path_px(paths_px: np.ndarray, points_px: np.ndarray) -> np.ndarray:
    """Signed distance [px] of each point (N×2) from its path (N×M×2 polylines, or one M×2
    for all, M ≥ 2): from its nearest point on the nearest segment, positive to the left of
    the path's direction."""
    paths = np.broadcast_to(paths_px, (len(points_px), *np.shape(paths_px)[-2:]))
    segment, _, distance = nearest_on_paths(points_px, paths)
    rows = np.arange(len(points_px))
    start = paths[rows, segment]
    direction, offset = paths[rows, segment + 1] - start, points_px - start
    side = direction[:, 0] * offset[:, 1] - direction[:, 1] * offset[:, 0]
    return np.where(side < 0, -1.0, 1.0) * distance


def seen_path_px(path_px: np.ndarray) -> np.ndarray | None:
    """A path (M×2 px) with the points the camera does not see (NaN: beyond its model's
    field, as a beam's at the container's rim can be) in the place of the nearest seen one
    at either end (on the line between the two about them within); None with fewer than two
    seen points."""
    seen = np.flatnonzero(np.isfinite(path_px).all(axis=1))
    if len(seen) < 2:
        return None
    index = np.arange(len(path_px))
    return np.column_stack([np.interp(index, seen, path_px[seen, axis]) for axis in (0, 1)])


def container_heights_mm(rig: Rig) -> np.ndarray:
    """Surface heights [mm] from the container's floor to its rim, no further apart than the
    default tracker's path samples: whatever heights a run's tracker searched (its
    `path_heights_mm`, not recorded with the spots), a spot lies on this path, and its offset
    from it is across the path, never along it beyond the path's end."""
    step_mm = float(np.diff(path_heights_mm(TrackerConfig()))[0])
    floor_mm = -rig.container.fill_height_mm
    rim_mm = rig.container.height_mm - rig.container.fill_height_mm
    return np.linspace(floor_mm, rim_mm, int(np.ceil((rim_mm - floor_mm) / step_mm)) + 1)


@dataclass(frozen=True)
class SigmaCheck:
    """A run's spots' scatter across their paths over their σ (RMS), from how many spots and
    measurements."""

    scatter_over_sigma: float
    spots: int
    measurements: int

    def line(self) -> str:
        """What a summary says of it."""
        low, high = HONEST_BAND
        verdict = ("the σ are honest" if low <= self.scatter_over_sigma <= high else
                   "the σ are too short" if self.scatter_over_sigma > high else
                   "the σ are too long")
        return (f"scatter across their beams' paths over their σ: RMS "
                f"{self.scatter_over_sigma:.2f}, {verdict} (about 1 when honest; "
                f"{self.spots} spots, {self.measurements} measurements)")


class PathScatter:
    """Sums per diode of its measured spots' offsets r [px] from its path and their weights
    w = 1/σ², from which `check` gives Σ (r − r̄)²·w over Σ (n − 1), r̄ each diode's mean."""

    def __init__(self, paths_px: dict[int, np.ndarray]) -> None:
        """`paths_px`: each diode's image path (M×2 px, the same M for all; a point the
        camera does not see, NaN, takes its nearest seen neighbour's place). A diode whose
        path has fewer than two seen points has none."""
        seen: dict[int, np.ndarray] = {}
        for laser_id, path in paths_px.items():
            seen_path = seen_path_px(path)
            if seen_path is not None:
                seen[laser_id] = seen_path
        self.rows = {laser_id: row for row, laser_id in enumerate(seen)}
        self.paths_px = np.stack(list(seen.values())) if seen else np.zeros((0, 2, 2))
        self.sums = np.zeros((len(seen), 5))   # per diode: n, Σr, Σr·w, Σr²·w, Σw

    @classmethod
    def for_rig(cls, rig: Rig) -> PathScatter:
        """Empty sums for the rig's tracked diodes' paths, over the container's whole height
        (`container_heights_mm`)."""
        return cls(beam_paths_px(rig, container_heights_mm(rig)))

    def add(self, laser_ids: np.ndarray, points_px: np.ndarray, sigmas_px: np.ndarray) -> None:
        """A frame's measured spots: their diodes, raw positions (N×2 px) and σ [px]; a spot
        without a path, a finite position or a σ > 0 is left out."""
        rows = np.array([self.rows.get(int(laser_id), -1) for laser_id in laser_ids], int)
        sigmas = np.asarray(sigmas_px, dtype=float).reshape(-1)
        points = np.asarray(points_px, dtype=float).reshape(-1, 2)
        keep = (rows >= 0) & np.isfinite(points).all(axis=1) & (sigmas > 0)
        if not keep.any():
            return
        offsets = across_path_px(self.paths_px[rows[keep]], points[keep])
        weights = 1.0 / sigmas[keep] ** 2
        np.add.at(self.sums, rows[keep], np.column_stack([
            np.ones_like(offsets), offsets, offsets * weights, offsets**2 * weights, weights]))

    def check(self) -> SigmaCheck | None:
        """The check over the diodes measured in MIN_FRAMES frames or more; None if none was."""
        counted = self.sums[self.sums[:, 0] >= MIN_FRAMES]
        if not len(counted):
            return None
        n, total, weighted, squares, weights = counted.T
        mean = total / n
        chi2 = float(np.sum(squares - 2 * mean * weighted + mean**2 * weights))
        dof = int(np.sum(n)) - len(counted)
        return SigmaCheck(float(np.sqrt(max(chi2, 0.0) / dof)), len(counted), int(np.sum(n)))
