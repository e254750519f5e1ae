"""One frame at a time: every diode's spot (Hampel-filtered) and the line, for the rig's paths."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation
from sds_model.errors import InputError
from sds_model.rig import Rig
from sds_recon.calibration.rig_model import across_axes
from sds_recon.triangulation import beam_image_path, beam_points_mm, line_image_path
from sds_recon.wall_reflection import wall_reflections_px

from sds_tracker.hampel import BankOutput, HampelBank
from sds_tracker.kernels import warm_up
from sds_tracker.line import (
    LineProfile,
    LineSettings,
    continued_within,
    end_is_dark,
    seek_line,
    track_line,
)
from sds_tracker.spots import (
    HAMPEL_REPLACED,
    LOST,
    NOT_FILTERED,
    SpotEstimate,
    SpotSettings,
    SpotTracker,
)


@dataclass(frozen=True)
class TrackedSpot:
    """A spot after the Hampel filter: filtered and raw position, uncertainty, peak, flags."""

    laser_id: int
    x_px: float
    y_px: float
    x_raw_px: float
    y_raw_px: float
    sigma_px: float
    peak: float
    flags: int


@dataclass(frozen=True)
class TrackerConfig:
    """Everything the tracker needs besides the rig."""

    spots: SpotSettings = field(default_factory=SpotSettings)
    line: LineSettings = field(default_factory=LineSettings)
    hampel_window: int = 5
    hampel_k: float = 3.0
    hampel_floor_px: float = 0.5
    path_heights_mm: tuple[float, float] = (-40.0, 40.0)   # surface heights the paths span
    stills: bool = False   # every frame a still of its own surface: no motion prior, no Hampel
    aperture_mm: float = 1.2   # a video's centroid aperture on the liquid (spot_apertures_px)


_DEFAULT = TrackerConfig()
TRACKING_PARAMETERS: dict[str, Any] = {
    "hampel_window": _DEFAULT.hampel_window, "window_px": _DEFAULT.spots.window_px,
    "threshold": _DEFAULT.spots.threshold, "prior_sigma_px": _DEFAULT.spots.prior_sigma_px,
    "path_tolerance_px": _DEFAULT.spots.path_tolerance_px, "line_band_px": _DEFAULT.line.band_px,
    "path_heights_mm": list(_DEFAULT.path_heights_mm), "seeds": [0.0],
    "stills": _DEFAULT.stills, "aperture_mm": _DEFAULT.aperture_mm}
"""The tracking parameters a node or `sds process` may set, with their defaults: those of
TrackerConfig, SpotSettings and LineSettings (one source; config/params/tracker.yaml documents
each, and a test holds it to these values)."""


def tracker_config(values: Mapping[str, Any]) -> TrackerConfig:
    """A TrackerConfig from tracking parameters (missing ones take their defaults)."""
    p = {**TRACKING_PARAMETERS, **values}
    return TrackerConfig(
        spots=SpotSettings(window_px=int(p["window_px"]),
                           prior_sigma_px=float(p["prior_sigma_px"]),
                           threshold=float(p["threshold"]),
                           path_tolerance_px=float(p["path_tolerance_px"])),
        line=LineSettings(band_px=int(p["line_band_px"]), threshold=float(p["threshold"])),
        hampel_window=int(p["hampel_window"]),
        path_heights_mm=(float(p["path_heights_mm"][0]), float(p["path_heights_mm"][1])),
        stills=bool(p["stills"]), aperture_mm=float(p["aperture_mm"]))


def parse_seeds(values: list[float]) -> dict[int, tuple[float, float]]:
    """Manual starting positions: [id, x, y, id, x, y, ...] (full-frame px); [0.0]: none."""
    if len(values) <= 1:
        return {}
    if len(values) % 3:
        raise InputError(f"seeds must be triples id, x, y; got {len(values)} numbers")
    return {int(values[i]): (float(values[i + 1]), float(values[i + 2]))
            for i in range(0, len(values), 3)}


def flat_line_px(rig: Rig) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of the line on the flat surface: where to look for it first."""
    if rig.line_laser is None:
        return np.zeros(0, int), np.zeros(0)
    pixels = line_image_path(rig, 0.0)
    pixels = pixels[np.isfinite(pixels).all(axis=1)]
    order = np.argsort(pixels[:, 1])
    rows = np.arange(int(np.ceil(pixels[order[0], 1])), int(pixels[order[-1], 1]) + 1)
    return rows, np.interp(rows, pixels[order, 1], pixels[order, 0])


def line_reach_px(rig: Rig, band_px: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rows the line can cross on any surface whose heights stay within the container's
    radius of the fill level (a surface tilted by up to 45°, a higher or lower fill), and on
    each the columns between which it can lie there: its image on level surfaces at −R, 0
    and +R (each held at its end column beyond its ends), `band_px` wider on either side;
    empty for a rig without a line laser."""
    if rig.line_laser is None:
        return np.zeros(0, int), np.zeros(0), np.zeros(0)
    radius_mm = rig.container.radius_mm
    images = []
    for height_mm in (-radius_mm, 0.0, radius_mm):
        pixels = line_image_path(rig, height_mm)
        pixels = pixels[np.isfinite(pixels).all(axis=1)]
        images.append(pixels[np.argsort(pixels[:, 1])])
    rows = np.arange(int(np.ceil(min(p[0, 1] for p in images))),
                     int(max(p[-1, 1] for p in images)) + 1)
    columns = [np.interp(rows, p[:, 1], p[:, 0]) for p in images]
    return rows, np.min(columns, axis=0) - band_px, np.max(columns, axis=0) + band_px


SEEK_PERIOD_FRAMES = 30
"""In a video whose line is lost, frames between searches over the line's whole reach (one
costs about 6 ms on a 4K image; a still and a video's first frame always get one)."""
PATH_SIGMAS = 3.0
"""A beam's image path is trusted to this many of its σ beyond `path_tolerance_px`."""


def path_heights_mm(config: TrackerConfig) -> np.ndarray:
    """The surface heights [mm] at which each diode's image path is sampled."""
    low, high = config.path_heights_mm
    return np.linspace(low, high, 15)


def beam_paths_px(rig: Rig, heights_mm: np.ndarray) -> dict[int, np.ndarray]:
    """Each tracked diode's image path (M×2 px) over the surface heights `heights_mm`."""
    return {d.laser_id: beam_image_path(rig, d.laser_id, heights_mm)
            for d in rig.tracked_diodes}


def path_sigma_px(rig: Rig, laser_id: int, heights_mm: np.ndarray) -> float:
    """How far [px] a diode's image path may be off where its beam's direction is uncertain:
    the largest move of the path over `heights_mm` when the direction turns by its σ
    (`direction_sigma_deg`, from `sds calibrate rig`) about either axis across it, about its
    emitter; 0 for a beam without a σ."""
    diode = rig.diode(laser_id)
    if not diode.direction_sigma_deg:
        return 0.0
    path = beam_image_path(rig, laser_id, heights_mm)
    moves = []
    for axis in across_axes(diode.direction):
        turned = Rotation.from_rotvec(np.radians(diode.direction_sigma_deg) * axis)
        tilted = replace(diode, direction=turned.apply(diode.direction))
        moved = replace(rig, diodes=(tilted,))
        moves.append(np.nanmax(np.linalg.norm(
            beam_image_path(moved, laser_id, heights_mm) - path, axis=1)))
    return float(max(moves))


def spot_apertures_px(rig: Rig, radius_mm: float) -> dict[int, float]:
    """Per tracked diode, a radius of `radius_mm` on the level surface at its spot, in image
    px (the mean of its images along the container's X and Y): a centroid aperture that holds
    the spot's light whatever its brightness. The default, 1.2 mm, is about 3 σ of the seed's
    spots (a 1.5 mm beam, 4 σ): 12 px on the 4K GoPro."""
    apertures = {}
    for diode in rig.tracked_diodes:
        spot = diode.point_at(-diode.emitter_mm[2] / diode.direction[2])
        pixels = rig.project(spot + np.array([[0.0, 0.0, 0.0], [radius_mm, 0.0, 0.0],
                                              [0.0, radius_mm, 0.0]]))
        apertures[diode.laser_id] = float(np.mean(np.linalg.norm(pixels[1:] - pixels[0],
                                                                 axis=1)))
    return apertures


class FrameTracker:
    """Spots and line per frame; spots come out `hampel_window // 2` frames late, filtered.
    With `stills` (images of different surfaces, not a video) every frame is tracked on its
    own: no prior from the previous frame's positions, no temporal filter, no latency."""

    def __init__(self, rig: Rig, config: TrackerConfig | None = None,
                 seeds: dict[int, tuple[float, float]] | None = None) -> None:
        self.config = config or TrackerConfig()
        heights = path_heights_mm(self.config)
        self.paths = beam_paths_px(rig, heights)
        widened = {d.laser_id: float(np.hypot(self.config.spots.path_tolerance_px,
                                              PATH_SIGMAS * path_sigma_px(rig, d.laser_id,
                                                                          heights)))
                   for d in rig.tracked_diodes}
        # A video's spots are measured in an aperture of one size on the liquid: under
        # speckle every grain counts; a still keeps the clipped centroid of its blob, since
        # its averaged frames hold the liquid's mirrored surroundings as wings (bench/README).
        apertures = None if self.config.stills or self.config.aperture_mm <= 0 else \
            spot_apertures_px(rig, self.config.aperture_mm)
        # A still's spots must lie on the surface the others show (`_on_the_surface`): a
        # still is a plane (a tilt table, a fill level), which the robust fit's form holds
        # exactly. Not a video's: a sloshing surface's higher modes leave it by several mm
        # (modes of 2 mm: 31 right points of 4000 beyond the limit, synthetic), and a spot
        # refused there stays unvouched, so refused again in the frames after.
        # Its spots are also kept apart from their own wall reflections: a still's clipped
        # centroid takes in a reflection its blob reaches (`_apart_from_reflections`).
        beams = {d.laser_id: beam_points_mm(rig, d.laser_id, heights)
                 for d in rig.tracked_diodes} if self.config.stills else None
        reflections = partial(wall_reflections_px, rig) if self.config.stills else None
        self.spots = SpotTracker(self.paths, self.config.spots, widened,
                                 apertures_px=apertures, beams_mm=beams,
                                 reflections_px=reflections)
        for laser_id, position in (seeds or {}).items():
            if laser_id not in self.paths:
                raise InputError(f"seed for laser {laser_id}, which the rig does not have")
            self.spots.previous[laser_id] = np.asarray(position, dtype=float)
        self.ids = list(self.paths)
        # What the calibration's stills showed a single frame's σ leaves out (speckle): for
        # the spots whose own light does not measure it (`SpotTracker.measures_own_speckle`)
        # an excess, for those whose light does a scale (`sigma_scale.video_sigma_scale`).
        calibration = rig.calibration or {}
        self.excess_sigma_px = float(calibration.get("spot_excess_sigma_px") or 0.0)
        self.sigma_scale = float(calibration.get("spot_sigma_scale") or 1.0)
        self.hampel = None if self.config.stills else HampelBank(
            self.config.hampel_window, self.config.hampel_k, self.config.hampel_floor_px)
        self._pending: dict[int, dict[int, SpotEstimate]] = {}
        # The line is sought on every row it can cross (beyond the level surface's line's
        # ends on a tilted surface or at another fill level), around that line at first.
        self._flat_rows, flat_x = flat_line_px(rig)
        self._line_rows, low_x, high_x = line_reach_px(rig, self.config.line.band_px)
        self._line_reach = (low_x, high_x)
        self._line_x = np.interp(self._line_rows, self._flat_rows, flat_x) \
            if len(self._flat_rows) else np.zeros(0)
        self._followed_rows = self._around(self._flat_rows, self.config.line.band_px)
        self._line_followed = False
        self._frames_since_seek = SEEK_PERIOD_FRAMES
        warm_up()

    def process(self, frame: int, red: np.ndarray, offset: tuple[int, int]
                ) -> tuple[list[tuple[int, list[TrackedSpot]]], LineProfile]:
        """Track one frame (red channel of the region at `offset`).

        Returns the spots of every frame whose Hampel window is now complete (frame, spots),
        and this frame's line profile.
        """
        estimates, line = self.measure(red, offset)
        self._pending[frame] = {e.laser_id: e for e in estimates}
        positions = np.array([[e.x_px, e.y_px] for e in estimates]).reshape(-1, 2)
        if self.hampel is None:
            unfiltered = BankOutput(frame, positions, positions, np.zeros(len(positions), bool))
            return [(frame, self._tracked(unfiltered))], line
        out = self.hampel.push(frame, positions, np.array([e.sigma_px for e in estimates]))
        ready = [] if out is None else [(out.frame, self._tracked(out))]
        return ready, line

    def measure(self, red: np.ndarray, offset: tuple[int, int]
                ) -> tuple[list[SpotEstimate], LineProfile]:
        """The next frame's spots (each diode's, before the Hampel filter) and line: the
        tracker's state (where the spots and the line were) moves on to this frame."""
        line = self._find_line(red, offset)
        found = len(line.x_px) > len(self._flat_rows) // 4
        # The spots get the line over the level surface's line's rows (a spot can hide the
        # line's end) and on to its ends where it runs beyond them: past its ends it has no
        # light to take away. An end within those rows with dark rows past it is the line's
        # own (a tilted surface's line is shorter): a spot beside it keeps all of its light
        # there, where the line's profile taken from rows the line never lit slid it across.
        lit = self._around(line.y_px if found else self._flat_rows, 0)
        if found:
            lit &= self._within_dark_ends(red, offset, line)
            # Follow the line: next frame looks around where it is now, on those rows and
            # `band_px` more at either end.
            self._line_x = np.interp(self._line_rows, line.y_px, line.x_px)
            self._followed_rows = self._around(line.y_px, self.config.line.band_px)
        # A still's line says nothing of the next image's.
        self._line_followed = found and self.hampel is not None
        if self.hampel is None:   # a still: where the spots were says nothing of this image
            self.spots.forget()
        # The line's light is kept out of the spots it passes (seen this frame, or expected).
        estimates = self.spots.update(red, offset, (self._line_rows[lit], self._line_x[lit]))
        return [self._calibrated_sigma(e) for e in estimates], line

    def _calibrated_sigma(self, estimate: SpotEstimate) -> SpotEstimate:
        """The spot with what the calibration's repeated frames showed its σ leaves out: a
        spot that measures its own speckle scaled by `sigma_scale`, any other widened by
        `excess_sigma_px`."""
        # Unchanged spots are not copied: a copy costs about 8 µs, 20 spots a frame.
        if self.spots.measures_own_speckle(estimate):
            if self.sigma_scale == 1.0:
                return estimate
            return replace(estimate, sigma_px=estimate.sigma_px * self.sigma_scale)
        if not self.excess_sigma_px:
            return estimate
        return replace(estimate, sigma_px=float(np.hypot(estimate.sigma_px,
                                                         self.excess_sigma_px)))

    def _find_line(self, red: np.ndarray, offset: tuple[int, int]) -> LineProfile:
        """This frame's line: around the last frame's where it was followed, else (the first
        frame, a still, a lost line every SEEK_PERIOD_FRAMES) also sought over its whole
        reach, the one found on more rows kept: on a tilted surface the line moves off the
        level surface's line with the height, beyond the band searched around it."""
        settings, noise = self.config.line, self.config.spots.read_noise
        followed = self._followed_rows
        line = self._continued(track_line(red, offset, self._line_x[followed],
                                          self._line_rows[followed], settings, noise))
        self._frames_since_seek += 1
        if self._line_followed or (self.hampel is not None
                                   and self._frames_since_seek < SEEK_PERIOD_FRAMES):
            return line
        self._frames_since_seek = 0
        low_x, high_x = self._line_reach
        sought = self._continued(seek_line(red, offset, self._line_rows, low_x, high_x, settings,
                                        noise))
        return sought if len(sought.x_px) > len(line.x_px) else line

    def _within_dark_ends(self, red: np.ndarray, offset: tuple[int, int], line: LineProfile
                          ) -> np.ndarray:
        """Which of the rows the line can cross (`_line_rows`) do not lie past an end of
        `line` that has dark rows beyond it (`line.end_is_dark`)."""
        within = np.ones(len(self._line_rows), bool)
        settings = self.config.line
        if end_is_dark(red, offset, line, 1, settings):
            within &= self._line_rows <= line.y_px[-1]
        if end_is_dark(red, offset, line, -1, settings):
            within &= self._line_rows >= line.y_px[0]
        return within

    def _around(self, rows: np.ndarray, margin_rows: int) -> np.ndarray:
        """Which of the rows the line can cross (`_line_rows`) lie between the first and the
        last of the level surface's line's rows and `rows` (full frame, ascending), or
        within `margin_rows` beyond them; none for a rig without a line laser."""
        if not len(self._flat_rows):
            return np.zeros(len(self._line_rows), bool)
        return (self._line_rows >= min(rows[0], self._flat_rows[0]) - margin_rows) & \
            (self._line_rows <= max(rows[-1], self._flat_rows[-1]) + margin_rows)

    def _continued(self, line: LineProfile) -> LineProfile:
        """`line.continued_within` the flat surface's line's rows."""
        if not len(self._flat_rows):
            return line
        return continued_within(line, self._flat_rows[0], self._flat_rows[-1], self.config.line)

    def unfiltered(self, frame: int) -> list[TrackedSpot]:
        """A frame's spots as measured, before its Hampel window closes (for a live view):
        position = raw position, flagged NOT_FILTERED; empty once the frame has left the
        window (its filtered spots were returned)."""
        return [TrackedSpot(e.laser_id, e.x_px, e.y_px, e.x_px, e.y_px, e.sigma_px, e.peak,
                            e.flags | NOT_FILTERED)
                for e in self._pending.get(frame, {}).values()]

    def flush(self) -> list[tuple[int, list[TrackedSpot]]]:
        """The last frames' spots at the end of a stream."""
        if self.hampel is None:
            return []
        return [(out.frame, self._tracked(out)) for out in self.hampel.flush()]

    def _tracked(self, out: BankOutput) -> list[TrackedSpot]:
        """The frame's spots with their filtered positions; the frame leaves the pending set."""
        pending = self._pending.pop(out.frame)
        spots = []
        for k, laser_id in enumerate(self.ids):
            raw = pending[laser_id]
            flags = raw.flags | (HAMPEL_REPLACED if out.replaced[k] else 0)
            spots.append(TrackedSpot(laser_id, float(out.filtered[k, 0]),
                                     float(out.filtered[k, 1]), raw.x_px, raw.y_px,
                                     raw.sigma_px, raw.peak, flags))
        return spots


def is_lost(spot: TrackedSpot) -> bool:
    """True when the spot has no position this frame."""
    return bool(spot.flags & LOST)
