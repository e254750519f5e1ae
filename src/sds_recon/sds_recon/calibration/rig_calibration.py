"""Self-calibration of a whole rig from blobs on known surfaces: identify, fit, verify.

1. Identify every diode's spots with the rig file's geometry, in a cone wide enough for the
   beams' leans plus the camera's unknown turn (identification.py).
2. Fit camera pose and beams jointly (self_calibration.py).
3. Identify again with the fitted rig, in a narrow cone and gate (diodes the rig file's
   camera pose hid come back), and fit again.
4. Spots whose residual exceeds `outlier_sigma` are left out, and a diode whose spots do not
   fit its own beam is named unidentified, never calibrated on a wrong blob.
5. With line pixels, the line laser's plane is started by a robust fit through the fitted
   camera; the line pixels within OUTLIER_MM of it (not the line's ends on the wall) then join
   the spots in one fit of camera, beams and plane. The line pixels' σ is scaled until their
   normalised RMS is 1 (the tracker's σ is a relative weight), and line pixels beyond
   `outlier_sigma` are left out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
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
    fit_plane_robust,
    points_on_surfaces,
)
from sds_recon.calibration.rig_model import LineObservations
from sds_recon.calibration.self_calibration import SelfCalibration, self_calibrate

LINE_FITS = 4
"""Most joint fits spent scaling the line pixels' σ and leaving out their outliers."""


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
    line: LineObservations | None = None     # the line pixels the joint fit used


def _observations(identification: Identification, blobs: list[np.ndarray],
                  covariances: list[np.ndarray]
                  ) -> tuple[list[int], np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    ids = sorted(identification.assigned)
    diode, frame, blob, pixels, covariance = [], [], [], [], []
    for index, laser_id in enumerate(ids):
        for f, b in sorted(identification.assigned[laser_id].items()):
            diode.append(index)
            frame.append(f)
            blob.append(b)
            pixels.append(blobs[f][b])
            covariance.append(covariances[f][b])
    return (ids, np.array(diode, int), np.array(frame, int), np.array(blob, int),
            np.array(pixels).reshape(-1, 2), np.array(covariance, float).reshape(-1, 2, 2))


def calibrate_rig(rig: Rig, surfaces: list[KnownSurface], blobs: list[np.ndarray],
                  blob_covariance_px2: list[np.ndarray], line: LineObservations | None = None,
                  settings: CalibrationSettings | None = None) -> RigCalibration:
    """Identify the spots and fit the rig (camera pose, beams, line plane) to them (`blobs`
    and `blob_covariance_px2`: per frame N×2 pixels and N×2×2 covariances [px²])."""
    s = settings or CalibrationSettings()
    wide = IdentificationSettings(cone_deg=s.cone_deg + s.camera_turn_deg, gate_mm=s.gate_mm)
    identification = identify_spots(rig, surfaces, blobs, wide)
    if not identification.assigned:
        raise ValueError("no diode could be identified on these surfaces: "
                         + "; ".join(f"{i}: {why}" for i, why in
                                     sorted(identification.unidentified.items())[:3]))
    ids, diode, frame, blob, pixels, covariance = _observations(identification, blobs,
                                                                blob_covariance_px2)
    fit = self_calibrate(rig, ids, surfaces, diode, frame, pixels, covariance,
                         s.fit_emitters, s.fit_camera)
    narrow = IdentificationSettings(cone_deg=s.cone_deg, gate_mm=s.refined_gate_mm)
    identification = identify_spots(fit.rig, surfaces, blobs, narrow)
    ids, diode, frame, blob, pixels, covariance = _observations(identification, blobs,
                                                                blob_covariance_px2)
    unidentified = dict(identification.unidentified)
    outliers: list[tuple[int, int, float]] = []
    while True:
        fit = self_calibrate(rig, ids, surfaces, diode, frame, pixels, covariance,
                             s.fit_emitters, s.fit_camera)
        normalised = fit.spot_residuals_sigma / np.sqrt(max(fit.chi2_per_dof, 1.0))
        keep = normalised <= s.outlier_sigma
        bad_diodes = [i for k, i in enumerate(ids)
                      if np.sqrt(np.mean(normalised[diode == k] ** 2)) > s.diode_rms_sigma
                      * np.sqrt(2)]
        if keep.all() and not bad_diodes:
            break
        for k, i in enumerate(ids):
            if i in bad_diodes:
                unidentified[i] = ("its spots do not fit one beam (RMS "
                                   f"{np.sqrt(np.mean(normalised[diode == k] ** 2)):.1f} σ)")
                keep &= diode != k
        outliers += [(ids[diode[k]], int(frame[k]), float(normalised[k]))
                     for k in np.flatnonzero(~keep) if ids[diode[k]] not in bad_diodes]
        remaining = sorted({ids[d] for d in diode[keep]})
        remap = {ids.index(i): n for n, i in enumerate(remaining)}
        diode = np.array([remap[d] for d in diode[keep]], int)
        frame, blob, pixels, covariance = frame[keep], blob[keep], pixels[keep], covariance[keep]
        ids = remaining
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
                          plane, used)


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
