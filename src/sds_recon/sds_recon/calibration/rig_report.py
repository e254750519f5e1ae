"""The calibrated rig file and the report of a self-calibration (what was fitted, how well)."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation
from sds_model.rig import Rig

from sds_recon.calibration.parameters import (
    CAMERA_ROTATION,
    CAMERA_SHIFT,
    LINE_PLANE,
)
from sds_recon.calibration.plan import (
    UNSEEN_TILTS_DEG,
    unseen_height_sigmas_mm,
    unseen_sensitivity,
    unseen_tilt_sigmas_deg,
)
from sds_recon.calibration.rig_calibration import RigCalibration
from sds_recon.calibration.self_calibration import SelfCalibration


def _deg(value: float) -> float:
    return float(f"{np.degrees(value):.4g}")


def _mm(value: float) -> float:
    return float(f"{value:.4g}")


def _sigma(value: float, in_degrees: bool) -> float | None:
    """A σ for the report: None for a parameter kept from the rig file (not fitted)."""
    if np.isnan(value):
        return None
    return _deg(value) if in_degrees else _mm(value)


def _plus_minus(sigma: float | None, digits: int = 3, unit: str = "") -> str:
    """"± σ unit", or "(kept from the rig file)" for a parameter that was not fitted (no
    unit: no number)."""
    if sigma is None:
        return "(kept from the rig file)"
    return f"± {sigma:.{digits}f}" + (f" {unit}" if unit else "")


def beam_sigma_deg(result: RigCalibration, laser_id: int) -> float:
    """One-sigma uncertainty of a beam's direction [deg] (the larger of its two tilts)."""
    fit = result.fit
    return float(np.degrees(max(fit.sigma_of(f"beam {laser_id} tilt a"),
                                fit.sigma_of(f"beam {laser_id} tilt b"))))


def calibrated_rig(nominal: Rig, result: RigCalibration,
                   report: dict[str, Any] | None = None) -> Rig:
    """The fitted rig with every beam's σ, unidentified diodes untracked, and the camera's and
    plane's uncertainties in its `calibration` record (from `report`, the fit's `rig_report`,
    where the caller has it already)."""
    fitted = result.fit.rig
    diodes = tuple(
        replace(d, direction_sigma_deg=beam_sigma_deg(result, d.laser_id), tracked=True)
        if d.laser_id in result.laser_ids else replace(nominal.diode(d.laser_id), tracked=False)
        for d in fitted.diodes)
    report = report or rig_report(nominal, result)
    record = {key: report[key] for key in ("model_check", "method", "frames", "spots",
                                           "rms_px", "camera", "line_laser", "unseen_surfaces",
                                           "unidentified", "not_determined",
                                           "weakly_determined")}
    fit = result.fit
    intrinsics = {name: fit.sigma_of(f"camera {name}") for name in nominal.camera_sigma}
    if not intrinsics:
        return replace(fitted, diodes=diodes, calibration=record)
    # The fitted intrinsics are the rig's own now: the camera goes into the rig file inline,
    # with their posterior σ, and the camera file stays as calibrated.
    return replace(fitted, diodes=diodes, calibration=record, camera_file=None,
                   camera_sigma={name: float(f"{sigma:.4g}")
                                 for name, sigma in intrinsics.items()})


def unseen_surfaces(result: RigCalibration) -> dict[str, Any]:
    """What the calibrated rig states it will measure: the one-σ errors its fit's covariance
    gives unseen surfaces tilted about the diagonal (plan.UNSEEN_TILTS_DEG, an axis no
    protocol uses), the worst tilt [deg] and the worst RMS of the points' heights [mm]."""
    fit = result.fit
    rig = replace(fit.rig, diodes=tuple(d if d.laser_id in result.laser_ids
                                        else replace(d, tracked=False) for d in fit.rig.diodes))
    sensitivity = unseen_sensitivity(rig)
    tilt_deg = unseen_tilt_sigmas_deg(sensitivity, fit.names, fit.covariance)
    height_mm = unseen_height_sigmas_mm(sensitivity, fit.names, fit.covariance)
    return {"tilts_about_diagonal_deg": list(UNSEEN_TILTS_DEG),
            "tilt_sigma_deg": float(f"{np.max(tilt_deg):.3g}"),
            "height_sigma_mm": float(f"{np.max(height_mm):.3g}")}


def rig_report(nominal: Rig, result: RigCalibration) -> dict[str, Any]:
    """Every parameter with its σ, residuals per beam and per frame, what was not determined."""
    fit = result.fit
    sigma = dict(zip(fit.names, fit.sigmas, strict=True))
    value = dict(zip(fit.names, fit.values, strict=True))
    rotation = Rotation.from_matrix(fit.rig.world_to_camera.rotation.T)
    camera = {
        "position_mm": [_mm(v) for v in fit.rig.camera_position_mm],
        "position_change_mm": [_mm(value[n]) for n in CAMERA_SHIFT],
        "position_sigma_mm": [_sigma(sigma[n], False) for n in CAMERA_SHIFT],
        "orientation_xyz_deg": [float(f"{v:.6g}") for v in rotation.as_euler("xyz",
                                                                             degrees=True)],
        "rotation_change_deg": [_deg(value[n]) for n in CAMERA_ROTATION],
        "rotation_sigma_deg": [_sigma(sigma[n], True) for n in CAMERA_ROTATION],
    }
    residual = np.linalg.norm(fit.spot_residuals_px, axis=1)
    beams = []
    for index, laser_id in enumerate(result.laser_ids):
        mine = result.diode == index
        d = fit.rig.diode(laser_id)
        before = nominal.diode(laser_id).direction
        beams.append({
            "id": laser_id, "spots": int(mine.sum()),
            "direction": [float(f"{v:.8g}") for v in d.direction],
            "direction_sigma_deg": float(f"{beam_sigma_deg(result, laser_id):.3g}"),
            "lean_from_vertical_deg": _deg(np.arccos(np.clip(-d.direction[2], -1, 1))),
            "change_deg": _deg(np.arccos(np.clip(d.direction @ before, -1, 1))),
            "rms_px": float(f"{np.sqrt(np.mean(residual[mine] ** 2)):.3g}"),
            "frames": sorted(int(f) for f in result.frame[mine])})
    frames = [{"frame": int(f), "spots": int(np.sum(result.frame == f)),
               "rms_px": float(f"{np.sqrt(np.mean(residual[result.frame == f] ** 2)):.3g}")}
              for f in sorted(set(result.frame.tolist()))]
    line: dict[str, Any] | None = None
    if result.line_plane is not None:
        plane = result.line_plane
        line = {"normal": [float(f"{v:.8g}") for v in plane.normal],
                "point_mm": [_mm(v) for v in plane.point_mm],
                "normal_sigma_deg": _sigma(float(np.max([sigma[n] for n in LINE_PLANE[:2]])),
                                           True),
                "offset_sigma_mm": _sigma(sigma[LINE_PLANE[2]], False),
                "points": plane.point_count, "left_out": plane.rejected,
                "rms_mm": _mm(plane.rms_mm),
                "rms_px": float(f"{np.sqrt(np.mean(fit.line_residuals_px**2)):.3g}")}
    check = result.check
    return {
        "model_check": {"explained": check.explained, "summary": check.summary(),
                        "chi2_per_dof": float(f"{check.chi2_per_dof:.4g}"), "dof": check.dof,
                        "expected": [float(f"{v:.4g}") for v in check.expected],
                        "likely_cause": check.likely_cause},
        "method": "joint least squares of camera pose, beams, uncertain emitters and known "
                  "surfaces and the line laser's plane, each declared tolerance a prior "
                  "(sds calibrate rig)",
        "frames": len(result.fit.model.surfaces), "spots": len(result.diode),
        "rms_px": float(f"{fit.rms_px:.3g}"), "chi2_per_dof": float(f"{fit.chi2_per_dof:.3g}"),
        "condition_number": float(f"{fit.condition_number:.3g}"),
        "camera": camera, "line_laser": line, "beams": beams, "per_frame": frames,
        "unseen_surfaces": unseen_surfaces(result),
        "unidentified": {str(k): v for k, v in sorted(result.unidentified.items())},
        "outliers": [{"id": i, "frame": f, "sigma": float(f"{s:.3g}")}
                     for i, f, s in result.outliers],
        "not_determined": dict(fit.fixed),
        "weakly_determined": _weak(fit.weak, sigma,
                                   dict(zip(fit.names, fit.table.scales, strict=True))),
        "surfaces": _surfaces(fit),
        "parameters": parameter_rows(fit),
    }


def parameter_rows(fit: SelfCalibration) -> list[dict[str, Any]]:
    """Every parameter of the fit: its kind, unit, declared prior σ, fitted change and σ, the
    change in σ of the prior (the pull), and what data determine it (degrees for angles)."""
    rows = []
    pulls = fit.pulls()
    for parameter, value, sigma, pull in zip(fit.table.parameters, fit.values, fit.sigmas,
                                             pulls, strict=True):
        angle = parameter.kind.unit == "rad"
        show = _deg if angle else _mm
        rows.append({"name": parameter.name, "kind": parameter.kind.name,
                     "unit": "deg" if angle else parameter.kind.unit,
                     "prior_sigma": show(parameter.prior_sigma) if parameter.has_prior else None,
                     "change": show(value), "sigma": _sigma(sigma, angle),
                     "pull": None if np.isnan(pull) else float(f"{pull:.3g}"),
                     "determined_by": parameter.advice})
    return rows


def _surfaces(fit: SelfCalibration) -> list[dict[str, Any]]:
    """Each known surface as read and as fitted (angles [deg], offset [mm]), with σ."""
    sigma = dict(zip(fit.names, fit.sigmas, strict=True))
    rows = []
    for index, (read, fitted) in enumerate(zip(fit.model.surfaces, fit.surfaces, strict=True)):
        row: dict[str, Any] = {
            "frame": index,
            "read_tilt_deg": [_deg(read.tilt_x_rad), _deg(read.tilt_y_rad)],
            "read_offset_mm": _mm(read.offset_mm),
            "declared_tilt_sigma_deg": [_deg(read.tilt_x_sigma_rad),
                                        _deg(read.tilt_y_sigma_rad)],
            "declared_offset_sigma_mm": _mm(read.offset_sigma_mm),
            "fitted_tilt_deg": [_deg(fitted.tilt_x_rad), _deg(fitted.tilt_y_rad)],
            "fitted_offset_mm": _mm(fitted.offset_mm)}
        tilt = [sigma.get(f"surface {index} tilt {axis}", np.nan) for axis in "xy"]
        row["tilt_sigma_deg"] = [_sigma(t, True) for t in tilt]
        row["offset_sigma_mm"] = _sigma(sigma.get(f"surface {index} offset", np.nan), False)
        rows.append(row)
    return rows


def _weak(weak: dict[str, str], sigma: dict[str, float], scale: dict[str, float]
          ) -> dict[str, dict[str, str]]:
    """Weakly determined parameters and their σ, grouped by the data that would determine them
    (the largest σ in the parameter's unit step, 1 mm or 1°, first)."""
    groups: dict[str, dict[str, str]] = {}
    for name in sorted(weak, key=lambda n: -sigma[n] / scale[n]):
        shown = f"{_mm(sigma[name])} mm" if scale[name] == 1.0 else f"{_deg(sigma[name])} deg"
        groups.setdefault(weak[name], {})[name] = shown
    return groups


def report_text(report: dict[str, Any]) -> str:
    """The report as a few tables for the terminal and the rig file's header."""
    camera = report["camera"]
    lines = [report["model_check"]["summary"],
             f"{report['spots']} spots on {report['frames']} known surfaces: RMS "
             f"{report['rms_px']} px, chi2/dof {report['chi2_per_dof']}, condition number "
             f"{report['condition_number']:.3g}",
             "camera position [mm] " + ", ".join(
                 f"{p:.3f} {_plus_minus(s)}" for p, s in zip(camera["position_mm"],
                                                             camera["position_sigma_mm"],
                                                             strict=True)),
             "camera turned [deg] about X, Y, Z " + ", ".join(
                 f"{c:+.3f} {_plus_minus(s)}" for c, s in zip(camera["rotation_change_deg"],
                                                              camera["rotation_sigma_deg"],
                                                              strict=True)),
             f"{'beam':>4} {'spots':>5} {'lean deg':>9} {'change deg':>10} {'sigma deg':>9} "
             f"{'rms px':>7}"]
    for beam in report["beams"]:
        lines.append(f"{beam['id']:>4} {beam['spots']:>5} {beam['lean_from_vertical_deg']:>9.3f} "
                     f"{beam['change_deg']:>10.3f} {beam['direction_sigma_deg']:>9.4f} "
                     f"{beam['rms_px']:>7.3f}")
    if report["line_laser"]:
        line = report["line_laser"]
        lines.append(f"line laser plane: {line['points']} points ({line['left_out']} left out), "
                     f"RMS {line['rms_px']} px / {line['rms_mm']} mm, normal "
                     f"{_plus_minus(line['normal_sigma_deg'], 4, 'deg')}, offset "
                     f"{_plus_minus(line['offset_sigma_mm'], 3, 'mm')}")
    unseen = report["unseen_surfaces"]
    lines.append(f"unseen surfaces (tilted {unseen['tilts_about_diagonal_deg'][0]:g}–"
                 f"{unseen['tilts_about_diagonal_deg'][-1]:g} deg about the diagonal), this "
                 f"calibration's own sigma: tilt ± {unseen['tilt_sigma_deg']:.3f} deg, heights "
                 f"± {unseen['height_sigma_mm']:.3f} mm")
    fitted_surfaces = [row for row in report["surfaces"]
                       if any(row["declared_tilt_sigma_deg"]) or row["declared_offset_sigma_mm"]]
    if fitted_surfaces:
        lines.append("surface  read tilt x, y [deg] +- sigma x, y     fitted tilt x, y [deg]   "
                     "read offset +- sigma   fitted offset [mm]")
        for row in fitted_surfaces:
            read, fitted = row["read_tilt_deg"], row["fitted_tilt_deg"]
            declared = "{:.3g}, {:.3g}".format(*row["declared_tilt_sigma_deg"])
            lines.append(
                f"{row['frame']:>7}  {read[0]:+8.3f} {read[1]:+8.3f}"
                f" +- {declared:<13}   {fitted[0]:+8.3f} "
                f"{fitted[1]:+8.3f}   {row['read_offset_mm']:+7.3f} +- "
                f"{row['declared_offset_sigma_mm']:<6.3g} {row['fitted_offset_mm']:+8.3f}")
    for laser_id, why in report["unidentified"].items():
        lines.append(f"diode {laser_id} not identified, not calibrated, not tracked: {why}")
    for name, advice in report["not_determined"].items():
        lines.append(f"not determined by these surfaces, kept from the rig file: {name} "
                     f"(needs {advice})")
    for advice, group in report["weakly_determined"].items():
        shown = ", ".join(f"{name} ± {value}" for name, value in list(group.items())[:3])
        more = f" and {len(group) - 3} more" if len(group) > 3 else ""
        lines.append(f"weakly determined: {shown}{more}; {advice} would pin them down")
    if report["outliers"]:
        lines.append(f"{len(report['outliers'])} spots left out as outliers")
    return "\n".join(lines)
