"""Camera pose and every beam in one weighted least-squares problem.

The seed calibrates each beam alone with the camera's pose assumed (Sec. 3.3.1) and blames
its Table 3 errors on that assumption. Here every spot on a known surface constrains the
camera and its own beam together: the residual is the offset [px] between the observed spot
and the projection of the beam's hit on that surface, whitened by the spot's covariance (a
spot beside the laser line is known well along the line, poorly across it). Parameters the data
cannot determine (their σ would exceed a limit) are not fitted: they keep the rig file's
value and the result says which extra data would fix them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np
from scipy.optimize import least_squares
from sds_model.rig import Rig

from sds_recon.calibration.lasers import KnownSurface
from sds_recon.calibration.rig_model import LineObservations, RigModel

LIMITS = {"camera rotation": np.radians(0.2), "camera": 1.0, "beam": np.radians(0.2),
          "emitter": 1.0, "line plane offset": 1.0, "line plane": np.radians(0.2)}
"""Largest one-sigma uncertainty [rad or mm] at which a parameter counts as determined."""

GOALS = {"camera rotation": np.radians(0.033), "camera": 0.1, "beam": np.radians(0.017),
         "emitter": 0.1, "line plane offset": 0.1, "line plane": np.radians(0.033)}
"""One-sigma uncertainty [rad or mm] above which a fitted parameter is reported as weakly
determined, with the data that would pin it down: a third of the error the calibration is
meant to reach (camera 0.1° and 0.3 mm, beams 0.05°). Tilts about one axis leave the camera's
rotation about that axis and the beams' common lean across it at σ ≈ 0.1° (the spots see
only their difference); three tilts about the second axis bring both to σ ≈ 0.005°."""

SIGMA_FLOOR_PX = 0.02
"""Least spot or line-pixel σ [px] the fit believes (in any direction)."""

NULL_SINGULAR = 1e-9
"""Singular values below this share of the largest (scaled Jacobian) are null directions."""

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
    "line plane": "tilts about the second axis (a line that runs along the tilt axis lies "
                  "in nearly every plane through it)",
}
"""What extra calibration data determines a parameter of each kind."""

T = TypeVar("T")


def _by_prefix(name: str, table: dict[str, T]) -> T:
    """The entry of `table` for parameter `name`: the first key that `name` starts with (the
    tables list the longer keys first)."""
    for prefix, entry in table.items():
        if name.startswith(prefix):
            return entry
    raise KeyError(name)


@dataclass(frozen=True)
class SelfCalibration:
    """The fitted rig with every parameter's value change and one-sigma uncertainty."""

    rig: Rig
    names: list[str]
    values: np.ndarray              # natural units (rad, mm), change from the rig file
    sigmas: np.ndarray              # one sigma, same units; NaN for fixed parameters
    fixed: dict[str, str]           # undetermined parameter → the data that would fix it
    weak: dict[str, str]            # fitted, but σ above GOALS → the data that would help
    condition_number: float
    rms_px: float                   # spot residuals
    chi2_per_dof: float
    spot_residuals_px: np.ndarray   # N×2, observed − predicted
    spot_residuals_sigma: np.ndarray  # N, the same in the spot's own σ (Mahalanobis)
    line_residuals_px: np.ndarray   # along the row, one per line pixel (empty without a line)
    model: RigModel = field(repr=False)

    def sigma_of(self, name: str) -> float:
        """One-sigma uncertainty of a parameter by name (NaN if fixed)."""
        return float(self.sigmas[self.names.index(name)])


def spot_whitening(covariance_px2: np.ndarray) -> np.ndarray:
    """Per spot (N×2×2 covariance [px²]) the matrix W with WᵀW = C⁻¹, the covariance's
    eigenvalues floored at SIGMA_FLOOR_PX²: |W r| is a residual r [px] in σ."""
    values, vectors = np.linalg.eigh(np.asarray(covariance_px2, dtype=float))
    values = np.maximum(values, SIGMA_FLOOR_PX**2)
    return np.swapaxes(vectors, 1, 2) / np.sqrt(values)[:, :, None]


def _jacobian(residuals: Callable[[np.ndarray], np.ndarray], values: np.ndarray,
              scales: np.ndarray) -> np.ndarray:
    """Forward-difference Jacobian of the residuals, steps of 1e-6 of each parameter's scale."""
    base = residuals(values)
    columns = []
    for k, scale in enumerate(scales):
        step = np.zeros_like(values)
        step[k] = 1e-6 * scale
        columns.append((residuals(values + step) - base) / step[k])
    return np.column_stack(columns)


def self_calibrate(rig: Rig, laser_ids: list[int], surfaces: list[KnownSurface],
                   diode: np.ndarray, frame: np.ndarray, pixels: np.ndarray,
                   covariance_px2: np.ndarray, fit_emitters: bool = False,
                   fit_camera: bool = True, line: LineObservations | None = None,
                   line_plane: tuple[np.ndarray, np.ndarray] | None = None) -> SelfCalibration:
    """Fit camera pose and beams (emitters optionally), and with `line` the line laser's plane
    (started at `line_plane`: normal, point [mm]), to spots and line pixels on known surfaces.

    `diode` indexes `laser_ids` and `frame` indexes `surfaces` for each spot (`pixels` N×2,
    `covariance_px2` N×2×2). Undetermined parameters are fixed one by one (the least
    determined first) until every fitted one is within LIMITS.
    """
    model = RigModel(rig, laser_ids, surfaces, fit_emitters, line, line_plane)
    whitening = spot_whitening(covariance_px2)
    line_sigma = np.maximum(line.sigma_px, SIGMA_FLOOR_PX) if line is not None else np.empty(0)
    free = np.ones(model.size, bool)
    if not fit_camera:
        free[:6] = False
    fixed: dict[str, str] = {}
    x = np.zeros(model.size)

    def residuals(values: np.ndarray) -> np.ndarray:
        full = x.copy()
        full[free] = values
        spot = np.einsum("nij,nj->ni", whitening, model.predict(full, diode, frame) - pixels)
        if line is None:
            return np.nan_to_num(spot.ravel(), nan=1e3)
        on_line = model.line_residuals(full) / line_sigma
        return np.nan_to_num(np.concatenate([spot.ravel(), on_line]), nan=1e3)

    scales = np.array(model.scales)

    def uncertainty(jacobian: np.ndarray, chi2: float) -> tuple[np.ndarray, np.ndarray]:
        """One-sigma uncertainties of the free parameters and the scaled singular values."""
        scaled = jacobian * scales[free]
        _, singular, rows = np.linalg.svd(scaled, full_matrices=False)
        # A direction the data do not constrain at all has an unbounded variance (a pseudo-
        # inverse would call it zero).
        inverse = np.where(singular > NULL_SINGULAR * singular[0], singular, 1e-30) ** -2.0
        variance = np.sum(rows**2 * inverse[:, None], axis=0) * max(chi2, 1.0)
        return np.sqrt(variance) * scales[free], singular

    def fix_worst(sigmas: np.ndarray) -> bool:
        """Fix the least determined free parameter if any is beyond its limit."""
        names = [n for n, f in zip(model.names, free, strict=True) if f]
        ratios = np.array([s / _by_prefix(n, LIMITS) for n, s in zip(names, sigmas, strict=True)])
        if not (ratios > 1).any():
            return False
        worst = names[int(np.argmax(ratios))]
        fixed[worst] = _by_prefix(worst, ADVICE)
        free[model.names.index(worst)] = False
        x[:] = 0.0
        return True

    # What the data cannot determine is fixed before solving (linearised at the rig file,
    # with the spots' own σ): left free, the solver runs off along those directions.
    while fix_worst(uncertainty(_jacobian(residuals, x[free], scales[free]), 1.0)[0]):
        pass
    while True:
        solution = least_squares(residuals, x[free], x_scale=scales[free], method="trf",
                                 xtol=1e-12, ftol=1e-12, gtol=1e-12)
        x[free] = solution.x
        dof = max(len(solution.fun) - free.sum(), 1)
        chi2 = float(np.sum(solution.fun**2) / dof)
        sigmas, singular = uncertainty(solution.jac, chi2)
        if not fix_worst(sigmas):
            break
    all_sigmas = np.full(model.size, np.nan)
    all_sigmas[free] = sigmas
    spot_residuals = pixels - model.predict(x, diode, frame)
    weak = {name: _by_prefix(name, ADVICE)
            for name, sigma in zip(model.names, all_sigmas, strict=True)
            if sigma > _by_prefix(name, GOALS)}
    return SelfCalibration(
        rig=model.to_rig(x), names=model.names, values=x.copy(), sigmas=all_sigmas,
        fixed=fixed, weak=weak, condition_number=float(singular[0] / max(singular[-1], 1e-300)),
        rms_px=float(np.sqrt(np.nanmean(np.sum(spot_residuals**2, axis=1)))),
        chi2_per_dof=chi2, spot_residuals_px=spot_residuals,
        spot_residuals_sigma=np.linalg.norm(np.einsum("nij,nj->ni", whitening, spot_residuals),
                                            axis=1),
        line_residuals_px=model.line_residuals(x) if line is not None else np.empty(0),
        model=model)
