"""Camera pose, every beam and the line laser's plane in one weighted least-squares problem.

The seed calibrates each beam alone with the camera's pose assumed (Sec. 3.3.1) and blames
its Table 3 errors on that assumption. Here every spot on a known surface constrains the
camera and its own beam together: the residual is the distance [px] between the observed spot
and the projection of the beam's hit on that surface, divided by the spot's σ; line pixels
add their hit's distance from the laser plane, divided by its σ [mm]. Parameters the data
cannot determine (their σ would exceed a limit) are not fitted: they keep the rig file's
value and the result says which extra data would fix them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from sds_recon.calibration.lasers import KnownSurface
from sds_recon.calibration.rig_model import RigModel
from sds_recon.rig import Rig

LIMITS = {"camera rotation": np.radians(0.2), "camera": 1.0, "beam": np.radians(0.2),
          "emitter": 1.0, "line plane tilt": np.radians(0.2), "line plane offset": 1.0}
"""Largest one-sigma uncertainty [rad or mm] at which a parameter counts as determined."""

ADVICE = {
    "camera rotation about Z": "tilts about the second axis",
    "camera X": "tilts about the second axis (or known emitters)",
    "camera Y": "tilts about the second axis (or known emitters)",
    "camera Z": "a level surface at a second known fill level",
    "camera rotation about X": "tilts about the second axis",
    "camera rotation about Y": "tilts about the second axis",
    "beam": "tilts about the second axis, or a second fill level (its spot hardly moves on "
            "these surfaces: it sits near the tilt axis)",
    "emitter": "a second fill level and tilts about the second axis",
    "line plane": "line pixels on more surfaces (tilts about both axes)",
}
"""What extra calibration data determines a parameter of each kind."""


def _limit(name: str) -> float:
    for prefix in ("camera rotation", "line plane tilt", "line plane offset", "camera", "beam",
                   "emitter"):
        if name.startswith(prefix):
            return LIMITS[prefix]
    raise KeyError(name)


def _advice(name: str) -> str:
    if name in ADVICE:
        return ADVICE[name]
    return ADVICE[name.split(" ")[0] if not name.startswith("line plane") else "line plane"]


@dataclass(frozen=True)
class LineObservations:
    """Line pixels on known surfaces: frame index, pixel (N×2), σ [px]."""

    frame: np.ndarray
    pixels: np.ndarray
    sigma_px: np.ndarray


@dataclass(frozen=True)
class SelfCalibration:
    """The fitted rig with every parameter's value change and one-sigma uncertainty."""

    rig: Rig
    names: list[str]
    values: np.ndarray              # natural units (rad, mm), change from the rig file
    sigmas: np.ndarray              # one sigma, same units; NaN for fixed parameters
    fixed: dict[str, str]           # undetermined parameter → the data that would fix it
    condition_number: float
    rms_px: float                   # spot residuals
    chi2_per_dof: float
    spot_residuals_px: np.ndarray   # N×2, observed − predicted
    line_residuals_mm: np.ndarray
    model: RigModel = field(repr=False)
    parameters: np.ndarray = field(repr=False)

    def sigma_of(self, name: str) -> float:
        """One-sigma uncertainty of a parameter by name (NaN if fixed)."""
        return float(self.sigmas[self.names.index(name)])


def _ground_px_per_mm(rig: Rig) -> float:
    """Image scale [px/mm] at the centre of the flat surface."""
    pixels = rig.project(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]))
    return float(np.mean(np.linalg.norm(pixels[1:] - pixels[0], axis=1)))


def self_calibrate(rig: Rig, laser_ids: list[int], surfaces: list[KnownSurface],
                   diode: np.ndarray, frame: np.ndarray, pixels: np.ndarray,
                   sigma_px: np.ndarray, line: LineObservations | None = None,
                   fit_emitters: bool = False, fit_camera: bool = True) -> SelfCalibration:
    """Fit camera pose, beams (emitters optionally) and line plane to spots on known surfaces.

    `diode` indexes `laser_ids` and `frame` indexes `surfaces` for each spot (`pixels` N×2,
    `sigma_px` N). Undetermined parameters are fixed one by one (the least determined first)
    until every fitted one is within LIMITS.
    """
    fit_plane = line is not None and len(line.frame) >= 3 and rig.line_laser is not None
    model = RigModel(rig, laser_ids, surfaces, fit_emitters, fit_plane)
    sigma = np.maximum(np.asarray(sigma_px, dtype=float), 0.02)
    if fit_plane:
        rays = rig.camera.pixel_to_ray(line.pixels)
        # The plane residual in mm: one pixel's footprint at the hit, times the pixel σ.
        line_sigma_mm = np.maximum(line.sigma_px, 0.05) / _ground_px_per_mm(rig)
        line_frame = line.frame
    free = np.ones(model.size, bool)
    if not fit_camera:
        free[:6] = False
    fixed: dict[str, str] = {}
    x = np.zeros(model.size)

    def residuals(values: np.ndarray) -> np.ndarray:
        full = x.copy()
        full[free] = values
        spot = ((model.predict(full, diode, frame) - pixels) / sigma[:, None]).ravel()
        if not fit_plane:
            return np.nan_to_num(spot, nan=1e3)
        plane = model.line_distances(full, rays, line_frame) / line_sigma_mm
        return np.nan_to_num(np.concatenate([spot, plane]), nan=1e3)

    scales = np.array(model.scales)
    while True:
        solution = least_squares(residuals, x[free], x_scale=scales[free], method="trf",
                                 xtol=1e-12, ftol=1e-12, gtol=1e-12)
        x[free] = solution.x
        jacobian = solution.jac
        dof = max(len(solution.fun) - free.sum(), 1)
        chi2 = float(np.sum(solution.fun**2) / dof)
        scaled = jacobian * scales[free]
        singular = np.linalg.svd(scaled, compute_uv=False)
        information = scaled.T @ scaled
        covariance = np.linalg.pinv(information, rcond=1e-12) * max(chi2, 1.0)
        sigmas = np.sqrt(np.clip(np.diag(covariance), 0, None)) * scales[free]
        names = [n for n, f in zip(model.names, free, strict=True) if f]
        ratios = np.array([s / _limit(n) for n, s in zip(names, sigmas, strict=True)])
        if not (ratios > 1).any():
            break
        worst = names[int(np.argmax(ratios))]
        fixed[worst] = _advice(worst)
        index = model.names.index(worst)
        free[index] = False
        x[index] = 0.0
    all_sigmas = np.full(model.size, np.nan)
    all_sigmas[free] = sigmas
    predicted = model.predict(x, diode, frame)
    spot_residuals = pixels - predicted
    line_residuals = (model.line_distances(x, rays, line_frame) if fit_plane
                      else np.zeros(0))
    return SelfCalibration(
        rig=model.to_rig(x), names=model.names, values=x.copy(), sigmas=all_sigmas,
        fixed=fixed, condition_number=float(singular[0] / max(singular[-1], 1e-300)),
        rms_px=float(np.sqrt(np.nanmean(np.sum(spot_residuals**2, axis=1)))),
        chi2_per_dof=chi2, spot_residuals_px=spot_residuals, line_residuals_mm=line_residuals,
        model=model, parameters=x.copy())
