"""Self-calibration of a whole rig from blobs on known surfaces: identify, fit, verify.

1. Identify every diode's spots with the rig file's geometry, in a cone wide enough for the
   beams' leans plus the camera's unknown turn (identification.py).
2. Fit camera pose and beams jointly (self_calibration.py).
3. Identify again with the fitted rig, in a narrow cone and gate (diodes the rig file's
   camera pose hid come back), and fit again.
4. Spots whose residual exceeds `outlier_sigma` are left out, and a diode whose spots do not
   fit its own beam is named unidentified, never calibrated on a wrong blob; but where the
   line through a diode's other spots misses one of them, that spot alone goes first (a
   wrong blob on the second fill level bends the beam towards itself, and the right spots
   then look like the outliers).
5. The diodes left out are identified once more, among the blobs no calibrated diode uses,
   through the camera the others determined and from the rig file's beams (not their own
   beams of step 2, which a wrong first choice had bent towards its blobs); whatever is
   found must pass step 4 in a joint fit with all the others. Two diodes ~10 mm apart whose
   beams each reach the other's spots within the gate on every surface were swapped in
   step 1, and step 3 kept the swap: 58 σ off at the ends, only 0.24 mm on the surface.
6. With line pixels, the line laser's plane is started by a robust fit through the fitted
   camera; the line pixels within OUTLIER_MM of it (not the line's ends on the wall) then join
   the spots in one fit of camera, beams and plane. The line pixels' σ is scaled until their
   normalised RMS is 1 (the tracker's σ is a relative weight), and line pixels beyond
   `outlier_sigma` are left out.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from sds_model.errors import InputError
from sds_model.rig import Rig

from sds_recon.calibration.identification import (
    Identification,
    IdentificationSettings,
    identify_spots,
)
from sds_recon.calibration.lasers import (
    OUTLIER_MM,
    KnownSurface,
    PlaneFitResult,
    fit_beam,
    fit_plane_robust,
    points_on_surfaces,
)
from sds_recon.calibration.model_check import PULL_FAIL, ModelCheck, check_model
from sds_recon.calibration.rig_model import LineObservations
from sds_recon.calibration.self_calibration import (
    SIGMA_FLOOR_PX,
    SelfCalibration,
    self_calibrate,
)

LINE_FITS = 4
"""Most joint fits spent scaling the line pixels' σ and leaving out their outliers."""
EMITTER_PULL_RATIO = 3.0
"""A diode's emitter pulled this many times further than the median emitter (and beyond the
model check's PULL_FAIL) has another diode's spots."""


@dataclass(frozen=True)
class CalibrationSettings:
    """Search and acceptance settings of the rig calibration."""

    cone_deg: float = 3.0                   # beams may lean this far from the rig file
    line_cone_deg: float = 5.0              # the line plane's normal may turn this far
    camera_turn_deg: float = 2.0            # the camera may be turned this far from the file
    gate_mm: float = 1.5                    # first identification's verification gate
    refined_gate_mm: float = 0.4            # after the first fit
    outlier_sigma: float = 6.0              # a spot this many σ off its prediction is dropped
    diode_rms_sigma: float = 4.0            # a diode whose spots fit this badly is dropped
    fit_emitters: bool = False
    fit_camera: bool = True


@dataclass(frozen=True)
class RigCalibration:
    """The outcome: the joint fit, the final identification and every dropped spot."""

    fit: SelfCalibration
    identification: Identification
    laser_ids: list[int]
    diode: np.ndarray           # per used spot: index into laser_ids
    frame: np.ndarray           # per used spot: frame
    blob: np.ndarray            # per used spot: blob index in its frame
    outliers: list[tuple[int, int, float]]   # (laser id, frame, residual in σ)
    unidentified: dict[int, str]
    line_plane: PlaneFitResult | None        # the line laser's plane, through the fitted camera
    check: ModelCheck                        # does the model explain the data (χ²/dof)?
    line: LineObservations | None = None     # the line pixels the joint fit used


@dataclass(frozen=True)
class _Spots:
    """The spots a joint fit uses: per spot its diode (index into `ids`), frame, blob index,
    pixel (N×2) and covariance (N×2×2 px²)."""

    ids: list[int]
    diode: np.ndarray
    frame: np.ndarray
    blob: np.ndarray
    pixels: np.ndarray
    covariance: np.ndarray

    def kept(self, keep: np.ndarray) -> _Spots:
        """The spots where `keep` holds, their diodes renumbered."""
        remaining = sorted({self.ids[d] for d in self.diode[keep]})
        remap = {self.ids.index(i): n for n, i in enumerate(remaining)}
        return _Spots(remaining, np.array([remap[d] for d in self.diode[keep]], int),
                      self.frame[keep], self.blob[keep], self.pixels[keep],
                      self.covariance[keep])

    def unused(self, blobs: list[np.ndarray]) -> list[list[int]]:
        """Per frame, the indices of the blobs these spots do not use."""
        used = set(zip(self.frame.tolist(), self.blob.tolist(), strict=True))
        return [[j for j in range(len(b)) if (f, j) not in used] for f, b in enumerate(blobs)]

    def assigned(self) -> dict[int, dict[int, int]]:
        """Laser id → frame → blob index."""
        return {i: dict(zip(self.frame[self.diode == k].tolist(),
                            self.blob[self.diode == k].tolist(), strict=True))
                for k, i in enumerate(self.ids)}


def _observations(assigned: dict[int, dict[int, int]], blobs: list[np.ndarray],
                  covariances: list[np.ndarray]) -> _Spots:
    """The spots of the assigned diodes (laser id → frame → blob index)."""
    ids = sorted(assigned)
    diode, frame, blob, pixels, covariance = [], [], [], [], []
    for index, laser_id in enumerate(ids):
        for f, b in sorted(assigned[laser_id].items()):
            diode.append(index)
            frame.append(f)
            blob.append(b)
            pixels.append(blobs[f][b])
            covariance.append(covariances[f][b])
    return _Spots(ids, np.array(diode, int), np.array(frame, int), np.array(blob, int),
                  np.array(pixels).reshape(-1, 2), np.array(covariance, float).reshape(-1, 2, 2))


def _fit_without_outliers(rig: Rig, surfaces: list[KnownSurface], spots: _Spots,
                          s: CalibrationSettings, unidentified: dict[int, str],
                          outliers: list[tuple[int, int, float]]
                          ) -> tuple[SelfCalibration, _Spots]:
    """Fit, leave out the spots beyond `outlier_sigma` and the diodes whose spots do not fit
    one beam (named in `unidentified`, the spots in `outliers`), until none is left out. Where
    the line through a diode's other spots misses one of them by more than `outlier_sigma`
    (`_odd_one_out`), that spot alone is left out of that diode in this round, whatever the
    fit's residuals say: a wrong blob on a surface few other spots reach (the second fill
    level) bends the beam and its emitter towards itself, and the right spots then look like
    the outliers, or the whole diode like a wrong one. A diode whose spots fit a beam only
    with its emitter moved beyond PULL_FAIL of its declared tolerance, and several times as
    far as the others' (EMITTER_PULL_RATIO × their median), has another diode's spots (two
    emitters 10 mm apart: a 0.3 mm tolerance would let the fit slide one onto the other's
    beam), and is left out too; when every emitter is pulled alike, the model is wrong, not
    an identity, and the model check says so. Each spot left out is listed with its
    residual in σ, or its miss where that chose it."""
    while True:
        if not spots.ids:
            raise InputError("no diode's spots fit its beam on these surfaces: "
                             + "; ".join(f"{i}: {why}" for i, why in
                                         sorted(unidentified.items())[:3]))
        fit = self_calibrate(rig, spots.ids, surfaces, spots.diode, spots.frame, spots.pixels,
                             spots.covariance, s.fit_emitters, s.fit_camera)
        chi_scale = np.sqrt(max(fit.chi2_per_dof, 1.0))
        normalised = fit.spot_residuals_sigma / chi_scale
        keep = normalised <= s.outlier_sigma
        rms = {i: float(np.sqrt(np.mean(normalised[spots.diode == k] ** 2)))
               for k, i in enumerate(spots.ids)}
        moved = _emitter_pulls(fit, spots.ids)
        worst = max(spots.ids, key=lambda i: moved[i])
        typical = float(np.median(list(moved.values())))
        swapped = moved[worst] > max(PULL_FAIL, EMITTER_PULL_RATIO * typical)
        bad_diodes = [i for i in spots.ids if rms[i] > s.diode_rms_sigma * np.sqrt(2)
                      or (swapped and i == worst)]
        if keep.all() and not bad_diodes:
            return fit, spots
        in_sigma, left_out = normalised.copy(), []
        for k, i in enumerate(spots.ids):
            rows = np.flatnonzero(spots.diode == k)
            if keep[rows].all() and i not in bad_diodes:
                continue
            odd = _odd_one_out(fit, spots, rows)
            if odd is not None and odd[1] / chi_scale > s.outlier_sigma:
                # One spot off the line the diode's others agree on goes, alone: it may
                # have bent the beam (or pulled the emitter) away from all the others.
                keep[rows] = True
                keep[rows[odd[0]]] = False
                in_sigma[rows[odd[0]]] = odd[1] / chi_scale
            elif i in bad_diodes:
                unidentified[i] = (f"its spots do not fit one beam (RMS {rms[i]:.1f} σ)"
                                   if not (swapped and i == worst) else
                                   f"its spots fit a beam only with its emitter moved "
                                   f"{moved[i]:.0f} σ of its tolerance (another diode's)")
                keep &= spots.diode != k
                left_out.append(i)
        outliers += [(spots.ids[spots.diode[k]], int(spots.frame[k]), float(in_sigma[k]))
                     for k in np.flatnonzero(~keep) if spots.ids[spots.diode[k]] not in left_out]
        spots = spots.kept(keep)


def _odd_one_out(fit: SelfCalibration, spots: _Spots, rows: np.ndarray
                 ) -> tuple[int, float] | None:
    """Of one diode's spots (`rows`), the one without which the others lie most nearly on one
    straight line, and how far that line misses it, in σ; None with fewer than four spots
    (of three, any two left fit a line) or a spot whose ray misses its surface. The spots'
    points are where the fitted camera's rays meet the fitted surfaces; a line is their free
    beam (`lasers.fit_beam`, emitter free, so that a wrong spot's pull on the joint fit's
    beam and emitter is not inherited); the miss is between the spot and where that line
    meets its surface, projected, in the spot's σ and the line's there in quadrature (a
    straight line's prediction σ: the others' spread along it sets how well it is known away
    from them). A spot that bent the joint fit's beam towards itself hides in that fit's
    residuals, and every other spot's line passes near it too; without it the others
    agree."""
    if len(rows) < 4:
        return None
    surfaces = [fit.surfaces[f] for f in spots.frame[rows]]
    points = points_on_surfaces(fit.rig, spots.pixels[rows], surfaces)
    if not np.isfinite(points).all():
        return None
    variance_px2 = np.maximum(np.trace(spots.covariance[rows], axis1=1, axis2=2) / 2,
                              SIGMA_FLOOR_PX**2)
    px_per_mm = fit.rig.surface_px_per_mm()
    laser_id = spots.ids[spots.diode[rows[0]]]
    spread = np.full(len(rows), np.inf)
    lines = []
    for j in range(len(rows)):
        others = np.delete(points, j, axis=0)
        # Placed at the others' centroid, the free beam's point is that centroid.
        line = fit_beam(laser_id, others, others.mean(axis=0), fit_emitter=True)
        offsets = others - line.emitter_mm
        along = offsets @ line.direction
        across_px = np.linalg.norm(offsets - np.outer(along, line.direction), axis=1) * px_per_mm
        spread[j] = float(np.mean(across_px**2 / np.delete(variance_px2, j)))
        lines.append((line, along))
    odd = int(np.argmin(spread))
    line, along = lines[odd]
    both_ways = surfaces[odd].intersect(line.emitter_mm,
                                        np.array([line.direction, -line.direction]))
    hit = both_ways[np.isfinite(both_ways[:, 0])]
    if not len(hit):
        return None
    reach = float((hit[0] - line.emitter_mm) @ line.direction)
    line_variance_px2 = float(np.mean(np.delete(variance_px2, odd))) * (
        1 / len(along) + reach**2 / max(float(along @ along), 1e-12))
    miss_px = float(np.linalg.norm(spots.pixels[rows[odd]] - fit.rig.project(hit[:1])[0]))
    return odd, miss_px / float(np.sqrt(variance_px2[odd] + line_variance_px2))


def _emitter_pulls(fit: SelfCalibration, laser_ids: list[int]) -> dict[int, float]:
    """Per diode, how far its emitter moved in σ of its declared tolerance (0 without one)."""
    pulls = dict(zip(fit.names, np.nan_to_num(np.abs(fit.pulls())), strict=True))
    return {i: max(pulls.get(f"emitter {i} a", 0.0), pulls.get(f"emitter {i} b", 0.0))
            for i in laser_ids}


def _identify_again(fitted: Rig, nominal: Rig, laser_ids: list[int],
                    surfaces: list[KnownSurface], blobs: list[np.ndarray],
                    free: list[list[int]], settings: IdentificationSettings
                    ) -> dict[int, dict[int, int]]:
    """The diodes `laser_ids` identified through the fitted camera from the rig file's beams,
    among the `free` blobs (per frame, blob indices): laser id → frame → blob index (the
    frames' own indices)."""
    beams = [d for d in nominal.diodes if d.laser_id in laser_ids]
    if not beams:
        return {}
    found = identify_spots(replace(fitted, diodes=tuple(beams)), surfaces,
                           [b[index] for b, index in zip(blobs, free, strict=True)], settings)
    return {i: {f: int(free[f][b]) for f, b in support.items()}
            for i, support in found.assigned.items()}


def calibrate_rig(rig: Rig, surfaces: list[KnownSurface], blobs: list[np.ndarray],
                  blob_covariance_px2: list[np.ndarray], line: LineObservations | None = None,
                  settings: CalibrationSettings | None = None) -> RigCalibration:
    """Identify the spots and fit the rig (camera pose, beams, line plane) to them (`blobs`
    and `blob_covariance_px2`: per frame N×2 pixels and N×2×2 covariances [px²])."""
    s = settings or CalibrationSettings()
    wide = IdentificationSettings(cone_deg=s.cone_deg + s.camera_turn_deg, gate_mm=s.gate_mm)
    identification = identify_spots(rig, surfaces, blobs, wide)
    if not identification.assigned:
        raise InputError("no diode could be identified on these surfaces: "
                         + "; ".join(f"{i}: {why}" for i, why in
                                     sorted(identification.unidentified.items())[:3]))
    spots = _observations(identification.assigned, blobs, blob_covariance_px2)
    fit = self_calibrate(rig, spots.ids, surfaces, spots.diode, spots.frame, spots.pixels,
                         spots.covariance, s.fit_emitters, s.fit_camera)
    narrow = IdentificationSettings(cone_deg=s.cone_deg, gate_mm=s.refined_gate_mm)
    identification = identify_spots(fit.rig, surfaces, blobs, narrow)
    unidentified = dict(identification.unidentified)
    outliers: list[tuple[int, int, float]] = []
    spots = _observations(identification.assigned, blobs, blob_covariance_px2)
    fit, spots = _fit_without_outliers(rig, surfaces, spots, s, unidentified, outliers)
    again = _identify_again(fit.rig, rig, sorted(unidentified), surfaces, blobs,
                            spots.unused(blobs), narrow)
    if again:
        retry_unidentified = {i: why for i, why in unidentified.items()
                              if i not in again}
        retry_outliers = list(outliers)
        retry_fit, retry_spots = _fit_without_outliers(
            rig, surfaces,
            _observations(spots.assigned() | again, blobs, blob_covariance_px2), s,
            retry_unidentified, retry_outliers)
        # Kept only if no diode that fitted before is lost (a wrong blob could pull the
        # camera away from a right one).
        if set(spots.ids) <= set(retry_spots.ids):
            fit, spots, unidentified, outliers = (retry_fit, retry_spots, retry_unidentified,
                                                  retry_outliers)
    identification = Identification(spots.assigned(), unidentified, spots.unused(blobs))
    ids, diode, frame, blob, pixels, covariance = (spots.ids, spots.diode, spots.frame,
                                                   spots.blob, spots.pixels, spots.covariance)
    plane, used = None, None
    if line is not None and len(line.frame) >= 3 and rig.line_laser is not None:
        plane, used = _line_plane(fit.rig, surfaces, line, s.line_cone_deg)
        # The fit starts from the rig file's normal, turned about a point among the line's
        # points: the robust plane's normal may be anywhere in a pencil of planes the points
        # hardly tell apart (a line running along the tilt axis), and what the data cannot
        # determine must stay at the rig file's value.
        start = (rig.line_laser.normal, plane.point_mm)
        for attempt in range(LINE_FITS):
            fit = self_calibrate(rig, ids, surfaces, diode, frame, pixels, covariance,
                                 s.fit_emitters, s.fit_camera, used, start)
            normalised = fit.line_residuals_px / used.sigma_px
            rms = float(np.sqrt(np.mean(normalised**2)))
            keep = np.abs(normalised) <= s.outlier_sigma * rms
            if (keep.all() and 0.8 < rms < 1.25) or attempt == LINE_FITS - 1:
                break
            used = LineObservations(used.frame[keep], used.pixels[keep],
                                    used.sigma_px[keep] * rms)
        plane = _plane_result(fit, surfaces, used, len(line.frame))
    return RigCalibration(fit, identification, ids, diode, frame, blob, outliers, unidentified,
                          plane, check_model(fit, ids, diode, frame), used)


def _line_plane(rig: Rig, surfaces: list[KnownSurface], line: LineObservations,
                cone_deg: float) -> tuple[PlaneFitResult, LineObservations]:
    """The robust plane through the line's points (its normal within `cone_deg` of the rig
    file's) and the line pixels within OUTLIER_MM of it."""
    assert rig.line_laser is not None   # calibrate_rig fits a plane only for a line laser
    points = points_on_surfaces(rig, line.pixels, [surfaces[f] for f in line.frame])
    plane = fit_plane_robust(points, near=rig.line_laser.normal, cone_deg=cone_deg)
    distance = (points - plane.point_mm) @ plane.normal
    return plane, line.subset(np.abs(distance) <= OUTLIER_MM)


def _plane_result(fit: SelfCalibration, surfaces: list[KnownSurface], used: LineObservations,
                  offered: int) -> PlaneFitResult:
    """The jointly fitted plane with the RMS distance [mm] of the line points it kept."""
    assert fit.rig.line_laser is not None
    normal = fit.rig.line_laser.normal
    point = fit.rig.line_laser.emitter_mm
    points = points_on_surfaces(fit.rig, used.pixels, [surfaces[f] for f in used.frame])
    distance = (points - point) @ normal
    return PlaneFitResult(normal, point, float(np.sqrt(np.nanmean(distance**2))), len(used.frame),
                          offered - len(used.frame))
