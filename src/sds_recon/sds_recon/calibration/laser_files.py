"""`sds calibrate lasers`: observations of known surfaces from files, an updated rig, a report."""

from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from sds_model.errors import InputError
from sds_model.rig import LaserDiode, LineLaser, Rig

from sds_recon.calibration.lasers import KnownSurface, calibrate_beams, calibrate_line_plane

SIGMA_COLUMNS = ("tilt_sigma_deg", "tilt_x_sigma_deg", "tilt_y_sigma_deg", "offset_sigma_mm")
"""The surfaces CSV's optional σ columns."""


def read_surfaces(path: Path) -> dict[int, KnownSurface]:
    """Known surface per frame from a CSV: frame, tilt_x_deg, tilt_y_deg[, offset_mm]
    [, tilt_sigma_deg (σ of each of the two angles), tilt_x_sigma_deg, tilt_y_sigma_deg (σ of
    one angle, instead of tilt_sigma_deg: a table read better across its axis than about it),
    offset_sigma_mm] (absent or empty σ: exact).

    The simulator's truth/frames.csv has the first four columns.
    """
    surfaces = {}
    with path.open() as file:
        for line, row in enumerate(csv.DictReader(file), start=2):
            try:
                frame = int(row["frame"])
                sigma = {name: float(row.get(name) or 0.0) for name in SIGMA_COLUMNS}
                # an angle's own column, where given (0 too), before the column of both
                tilt_sigma_deg = [sigma[column] if row.get(column) else sigma["tilt_sigma_deg"]
                                  for column in ("tilt_x_sigma_deg", "tilt_y_sigma_deg")]
                surface = KnownSurface(
                    float(row.get("offset_mm") or 0.0), np.radians(float(row["tilt_x_deg"])),
                    np.radians(float(row["tilt_y_deg"])), np.radians(tilt_sigma_deg[0]),
                    np.radians(tilt_sigma_deg[1]), sigma["offset_sigma_mm"])
            except (KeyError, TypeError, ValueError) as error:
                raise InputError(f"{path}: line {line} needs frame, tilt_x_deg, tilt_y_deg "
                                 f"(and any offset or σ column) as numbers: {error!r}"
                                 ) from error
            if not all(value >= 0 for value in sigma.values()):
                raise InputError(f"{path}: line {line}: {', '.join(SIGMA_COLUMNS)} must not be "
                                 "negative")
            surfaces[frame] = surface
    return surfaces


def read_spots(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frame, laser id and full-resolution pixel of every visible spot in a CSV
    (frame, laser_id, x_px, y_px[, visible]): the tracker's or the simulator's spots.csv."""
    frames, ids, pixels = [], [], []
    with path.open() as file:
        for row in csv.DictReader(file):
            try:
                if row.get("visible", "1") in ("0", "False", "false"):
                    continue
                x, y = float(row["x_px"]), float(row["y_px"])
                if np.isfinite(x) and np.isfinite(y):
                    frames.append(int(row["frame"]))
                    ids.append(int(row["laser_id"]))
                    pixels.append((x, y))
            except (KeyError, ValueError) as error:
                raise InputError(f"{path}: needs frame, laser_id, x_px, y_px: {error!r}") from error
    return np.array(frames), np.array(ids), np.array(pixels).reshape(-1, 2)


def read_line(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Frames and pixels (x, row) of the line from an NPZ with line_x_px (frames × rows)."""
    line = np.load(path)["line_x_px"]
    frames, rows = np.nonzero(np.isfinite(line))
    return frames, np.column_stack([line[frames, rows], rows]).astype(float)


def calibrate_lasers(rig: Rig, spots: Path, surfaces: Path, line: Path | None = None,
                     fit_emitters: bool = False) -> tuple[Rig, dict[str, Any]]:
    """The rig with calibrated beams (and line plane) from files, and a report."""
    known = read_surfaces(surfaces)
    frames, ids, pixels = read_spots(spots)
    missing = sorted(set(frames.tolist()) - set(known))
    if missing:
        raise InputError(f"no known surface for frames {missing[:10]} of {spots}")
    line_observations = read_line(line) if line is not None else None
    return calibrate_from_observations(rig, known, frames, ids, pixels, line_observations,
                                       fit_emitters)


def calibrate_from_observations(rig: Rig, known: dict[int, KnownSurface], frames: np.ndarray,
                                ids: np.ndarray, pixels: np.ndarray,
                                line: tuple[np.ndarray, np.ndarray] | None = None,
                                fit_emitters: bool = False) -> tuple[Rig, dict[str, Any]]:
    """The rig with calibrated beams (and line plane, from (frames, pixels) of the line) from
    spots on known surfaces, and a report of what changed."""
    fits = calibrate_beams(rig, ids, pixels, [known[f] for f in frames], fit_emitters)
    by_id = {fit.laser_id: fit for fit in fits}
    diodes = []
    report: dict[str, Any] = {"surfaces": len(set(frames.tolist())), "beams": []}
    for diode in rig.diodes:
        fit = by_id.get(diode.laser_id)
        if fit is None:
            diodes.append(diode)
            report["beams"].append({"id": diode.laser_id, "points": 0, "calibrated": False})
            continue
        diodes.append(LaserDiode(diode.laser_id, diode.ring, fit.emitter_mm, fit.direction))
        change = np.degrees(np.arccos(np.clip(fit.direction @ diode.direction, -1, 1)))
        lean = np.degrees(np.arccos(np.clip(-fit.direction[2], -1, 1)))
        report["beams"].append({
            "id": diode.laser_id, "points": fit.point_count, "calibrated": True,
            "direction": fit.direction.tolist(), "lean_from_vertical_deg": float(lean),
            "change_deg": float(change), "rms_mm": fit.rms_mm,
            "direction_sigma_deg": float(np.degrees(fit.direction_sigma_rad)),
            "emitter_mm": fit.emitter_mm.tolist()})
    calibrated = replace(rig, diodes=tuple(diodes))
    if line is not None and rig.line_laser is not None:
        line_frames, line_pixels = line
        plane = calibrate_line_plane(rig, line_pixels, [known[f] for f in line_frames])
        emitter = rig.line_laser.emitter_mm
        emitter = emitter - ((emitter - plane.point_mm) @ plane.normal) * plane.normal
        calibrated = replace(calibrated, line_laser=LineLaser(emitter, plane.normal))
        change = np.degrees(np.arccos(np.clip(plane.normal @ rig.line_laser.normal, -1, 1)))
        report["line_laser"] = {"normal": plane.normal.tolist(), "rms_mm": plane.rms_mm,
                                "points": plane.point_count, "change_deg": float(change)}
    return calibrated, report


def report_text(report: dict[str, Any]) -> str:
    """The report as a table."""
    lines = [f"beams from {report['surfaces']} known surfaces",
             f"{'id':>3} {'points':>6} {'lean deg':>9} {'change deg':>10} {'sigma deg':>9} "
             f"{'rms mm':>7}"]
    for beam in report["beams"]:
        if not beam["calibrated"]:
            lines.append(f"{beam['id']:>3} {0:>6}  not seen: kept as it was")
            continue
        lines.append(f"{beam['id']:>3} {beam['points']:>6} {beam['lean_from_vertical_deg']:>9.3f} "
                     f"{beam['change_deg']:>10.3f} {beam['direction_sigma_deg']:>9.4f} "
                     f"{beam['rms_mm']:>7.3f}")
    if "line_laser" in report:
        line = report["line_laser"]
        lines.append(f"line laser plane: {line['points']} points, rms {line['rms_mm']:.3f} mm, "
                     f"normal moved {line['change_deg']:.3f} deg")
    return "\n".join(lines)
