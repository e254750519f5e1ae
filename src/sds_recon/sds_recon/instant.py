"""The surface at one instant under a rolling shutter: each frame's fits at the frame's time.

A rolling shutter exposes each spot at its row's time (`RollingShutter`), up to the readout
(20-30 ms) after the frame's stamp, so one frame's points are not one surface: fitted as they
are, the plane and the modes mix instants, and the modal amplitudes mix phases. Each spot's
height is therefore carried to the frame's time along its own diode's history: the parabola
through its heights in the frame before, this frame and the frame after, each at its sample
time (only two of them: the line through them; alone: as measured). The frame's time lies
between the previous sample and this one, so this interpolates (error O(h³): a few µm for the
seed's modes at 30 fps). The point moves along its beam to that height, and the frame is
fitted as ever (`fit_surface`). The fits of a frame therefore come one frame later; with a
global shutter they come at once, unchanged.
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass, replace
from typing import Generic, TypeVar

import numpy as np
from sds_model.rig import Rig

from sds_recon.reconstruction import SurfaceFits, SurfacePoints, fit_surface

Key = TypeVar("Key", bound=Hashable)
"""What names a frame for the caller (an index, a message)."""


def sample_offsets_s(rig: Rig, points: SurfacePoints) -> np.ndarray:
    """How long after the frame's stamp each point's image row was exposed [s] (the rig's
    camera's rolling shutter; 0 for a global shutter; NaN where the row is not known)."""
    rows = points.row_px if points.row_px is not None else np.full(len(points.laser_ids),
                                                                   np.nan)
    return rig.camera_shutter.row_time_s(rows, rig.camera.height_px)


@dataclass(frozen=True)
class TimedPoints(Generic[Key]):
    """One frame's spot points with the frame's time and each point's sample time [s]."""

    key: Key
    time_s: float
    points: SurfacePoints
    sample_time_s: np.ndarray


def heights_at_frame_time(frame: TimedPoints[Key], before: TimedPoints[Key] | None,
                          after: TimedPoints[Key] | None) -> np.ndarray:
    """Each of `frame`'s spot heights [mm] at the frame's time, from its diode's heights in
    the neighbouring frames at their sample times (see the module)."""
    heights = frame.points.points_mm[:, 2].copy()
    neighbours = [n for n in (before, after) if n is not None]
    lookup = [{int(i): (float(t), float(z)) for i, t, z in zip(
        n.points.laser_ids, n.sample_time_s, n.points.points_mm[:, 2], strict=True)}
        for n in neighbours]
    for row, (laser_id, time_s) in enumerate(zip(frame.points.laser_ids, frame.sample_time_s,
                                                 strict=True)):
        samples = [(float(time_s), float(heights[row]))]
        samples += [found[int(laser_id)] for found in lookup if int(laser_id) in found]
        if len(samples) < 2 or not np.isfinite(samples).all():
            continue
        times, values = np.array(samples).T
        heights[row] = float(np.polyval(np.polyfit(times - frame.time_s, values,
                                                   len(samples) - 1), 0.0))
    return heights


@dataclass(frozen=True)
class InstantFrame(Generic[Key]):
    """A frame's surface at its time: its fits and the spot points they used (each carried to
    the frame's time; the points as measured for a global shutter)."""

    key: Key
    fits: SurfaceFits
    points: SurfacePoints


class InstantFits(Generic[Key]):
    """Fits each frame at its time (`push` a frame, get the frame before; `flush` at the
    end); with the rig's camera a global shutter, each frame comes back at once."""

    def __init__(self, rig: Rig) -> None:
        self.rig = rig
        self.timed = rig.camera_shutter.readout_s > 0
        self._directions = {d.laser_id: d.direction for d in rig.diodes}
        self._before: TimedPoints[Key] | None = None
        self._held: TimedPoints[Key] | None = None

    def push(self, key: Key, time_s: float, points: SurfacePoints,
             recorded_offsets_s: np.ndarray | None = None) -> list[InstantFrame[Key]]:
        """A frame's points in (their sample times from their image rows, or
        `recorded_offsets_s` after `time_s`, a recorded cloud's); the frame before out, now
        that its neighbours are known (this frame, for a global shutter)."""
        if not self.timed:
            return [InstantFrame(key, fit_surface(points, self.rig.container.radius_mm),
                                 points)]
        offsets = sample_offsets_s(self.rig, points) if recorded_offsets_s is None \
            else recorded_offsets_s
        frame = TimedPoints(key, time_s, points, time_s + offsets)
        done = self._fit(self._held, frame) if self._held is not None else []
        self._before, self._held = self._held, frame
        return done

    def flush(self) -> list[InstantFrame[Key]]:
        """The last frame (no frame after it)."""
        done = self._fit(self._held, None) if self._held is not None else []
        self._before = self._held = None
        return done

    def _fit(self, frame: TimedPoints[Key], after: TimedPoints[Key] | None
             ) -> list[InstantFrame[Key]]:
        points = frame.points
        shift = heights_at_frame_time(frame, self._before, after) - points.points_mm[:, 2]
        directions = np.array([self._directions[int(i)] for i in points.laser_ids]).reshape(-1, 3)
        # Along the beam to the new height: a leaning beam's spot moves sideways too.
        moved = points.points_mm + (shift / directions[:, 2])[:, None] * directions
        at_frame_time = replace(points, points_mm=moved)
        return [InstantFrame(frame.key, fit_surface(at_frame_time,
                                                    self.rig.container.radius_mm),
                             at_frame_time)]
