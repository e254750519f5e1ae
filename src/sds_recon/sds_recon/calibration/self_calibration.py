"""Camera pose, every beam, the known surfaces and the line plane in one weighted least-squares
problem (a bundle adjustment of the rig), its uncertainties and the check of its model.

The seed calibrates each beam alone with the camera's pose assumed (Sec. 3.3.1) and blames
its Table 3 errors on that assumption. Here every spot on a known surface constrains the
camera, its own beam and that surface together: the residual is the offset [px] between the
observed spot and the projection of the beam's hit on the surface, whitened by the spot's
covariance (a spot beside the laser line is known well along the line, poorly across it).
Whatever the user declared uncertain (rig file `tolerances:`, the surfaces CSV's σ columns)
is a parameter with its prior as a residual; parameters without a prior that the data cannot
determine (their σ would exceed a limit) are not fitted: they keep the rig file's value and
the result says which extra data would fix them. χ²/dof is then checked against its spread
for the degrees of freedom (`model_check.py`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from sds_model.rig import Rig

from sds_recon.calibration.lasers import KnownSurface
from sds_recon.calibration.parameters import (
    SURFACE_OFFSET_KIND,
    SURFACE_TILT_KIND,
    ParameterTable,
)
from sds_recon.calibration.rig_model import LineObservations, RigModel

SIGMA_FLOOR_PX = 0.02
"""Least spot or line-pixel σ [px] the fit believes (in any direction)."""

DETERMINATION_SPOT_SIGMA_PX = 0.05
"""The spots' σ [px] at which a parameter's σ is held against its limit to judge whether the
data determine it (about the tracker's on a 4K spot): that is a question of the calibration
data's geometry, not of how noisy its spots are. Judged at the spots' own σ and χ², noisier
spots (or σ understated: χ²/dof of 60) left the camera's rotation kept from the rig file
although the protocol's tilts about the second axis determine it; such a fit now fits it,
and its σ (scaled by its χ²/dof) says how well. Only the spots' and line pixels' σ are set
to it: the declared tolerances stay as declared. Scaled with them, the precise spots of
averaged stills made the camera's yaw, which the emitters' and the table readings' tolerances
determine, look undetermined; kept from the rig file, a turned camera turned the fitted
emitters and surfaces with it, and unseen tilts were off across their axis."""
NULL_SINGULAR = 1e-9
"""Singular values below this share of the largest (scaled Jacobian) are null directions."""


@dataclass(frozen=True)
class SelfCalibration:
    """The fitted rig with every parameter's value change and one-sigma uncertainty."""

    rig: Rig
    table: ParameterTable
    values: np.ndarray              # natural units (rad, mm), change from the rig file
    sigmas: np.ndarray              # one sigma, same units; NaN for fixed parameters
    covariance: np.ndarray          # the parameters' covariance, same units; NaN where fixed
    fixed: dict[str, str]           # undetermined parameter → the data that would fix it
    weak: dict[str, str]            # fitted, but σ above its goal → the data that would help
    condition_number: float
    rms_px: float                   # spot residuals
    chi2: float                     # sum of squared whitened residuals (spots, line, priors)
    dof: int                        # residuals − free parameters
    spot_residuals_px: np.ndarray   # N×2, observed − predicted
    spot_residuals_sigma: np.ndarray  # N, the same in the spot's own σ (Mahalanobis)
    line_residuals_px: np.ndarray   # along the row, one per line pixel (empty without a line)
    surfaces: list[KnownSurface]    # the known surfaces as fitted
    model: RigModel = field(repr=False)

    @property
    def names(self) -> list[str]:
        """Every parameter's name, in the order of `values` and `sigmas`."""
        return self.table.names

    @property
    def chi2_per_dof(self) -> float:
        """χ² per degree of freedom: about 1 when the model and the σ explain the data."""
        return self.chi2 / max(self.dof, 1)

    def sigma_of(self, name: str) -> float:
        """One-sigma uncertainty of a parameter by name (NaN if fixed)."""
        return float(self.sigmas[self.table.index(name)])

    def pulls(self) -> np.ndarray:
        """Each parameter's change in its prior's σ (NaN where none was declared): beyond
        about 3 the declared tolerance is too tight for what the data require."""
        prior = self.table.prior_sigmas
        with np.errstate(invalid="ignore"):
            return np.where(np.isfinite(prior), self.values / prior, np.nan)


def spot_whitening(covariance_px2: np.ndarray) -> np.ndarray:
    """Per spot (N×2×2 covariance [px²]) the matrix W with WᵀW = C⁻¹, the covariance's
    eigenvalues floored at SIGMA_FLOOR_PX²: |W r| is a residual r [px] in σ."""
    values, vectors = np.linalg.eigh(np.asarray(covariance_px2, dtype=float))
    values = np.maximum(values, SIGMA_FLOOR_PX**2)
    return np.swapaxes(vectors, 1, 2) / np.sqrt(values)[:, :, None]


@dataclass(frozen=True)
class Observations:
    """What the fit explains: spots (diode index into the model's laser ids, frame index into
    its surfaces, pixel N×2, whitening N×2×2) and line pixels' σ (empty without a line)."""

    diode: np.ndarray
    frame: np.ndarray
    pixels: np.ndarray
    whitening: np.ndarray
    line_sigma_px: np.ndarray


def residuals(model: RigModel, observations: Observations, x: np.ndarray) -> np.ndarray:
    """Every whitened residual at the full parameter vector `x`: spots (2 each), line pixels,
    declared tolerances, in that order (`residual_rows` follows it); NaN (a beam that misses
    its surface) counts as 1000 σ."""
    o = observations
    spot = np.einsum("nij,nj->ni", o.whitening, model.predict(x, o.diode, o.frame) - o.pixels)
    parts = [spot.ravel()]
    if model.line is not None:
        parts.append(model.line_residuals(x) / o.line_sigma_px)
    parts.append(model.prior_residuals(x))
    return np.nan_to_num(np.concatenate(parts), nan=1e3)


def residual_rows(model: RigModel, observations: Observations) -> list[np.ndarray]:
    """For each parameter, the rows of `residuals` that depend on it: a spot's two rows on
    the camera, its beam and its surface; a line pixel's on the camera, its surface and the
    line plane; a declared tolerance's on its parameter alone."""
    rows: list[list[np.ndarray]] = [[] for _ in range(model.size)]
    o = observations
    for diode, frame in set(zip(o.diode.tolist(), o.frame.tolist(), strict=True)):
        spots = np.flatnonzero((o.diode == diode) & (o.frame == frame))
        for parameter in model.spot_parameters(diode, frame):
            rows[parameter] += [2 * spots, 2 * spots + 1]
    first_line_row = 2 * len(o.diode)
    if model.line is not None:
        for frame in np.unique(model.line.frame).tolist():
            pixels = first_line_row + np.flatnonzero(model.line.frame == frame)
            for parameter in model.line_parameters(frame):
                rows[parameter].append(pixels)
    first_prior_row = first_line_row + (len(model.line.frame) if model.line is not None else 0)
    for k, parameter in enumerate(model.prior_parameters):
        rows[parameter].append(np.array([first_prior_row + k]))
    return [np.unique(np.concatenate(r)) if r else np.empty(0, int) for r in rows]


def column_groups(rows: list[np.ndarray]) -> list[np.ndarray]:
    """Columns (indices into `rows`) in groups that share no row, greedily in order: one
    residual evaluation steps a whole group."""
    row_count = max((int(r.max()) + 1 for r in rows if len(r)), default=0)
    taken: list[np.ndarray] = []
    members: list[list[int]] = []
    for column, column_rows in enumerate(rows):
        for mask, group in zip(taken, members, strict=True):
            if not mask[column_rows].any():
                mask[column_rows] = True
                group.append(column)
                break
        else:
            mask = np.zeros(row_count, bool)
            mask[column_rows] = True
            taken.append(mask)
            members.append([column])
    return [np.array(group) for group in members]


def forward_differences(residuals_of: Callable[[np.ndarray], np.ndarray], values: np.ndarray,
                        base: np.ndarray, steps: np.ndarray, rows: list[np.ndarray],
                        groups: list[np.ndarray]) -> np.ndarray:
    """Forward-difference Jacobian of `residuals_of` at `values` (residuals `base`), column j
    stepped by `steps[j]` over its `rows`; each of `groups` (`column_groups`) in one
    evaluation. The same as stepping one column at a time, for a fraction of the cost."""
    derivatives = np.zeros((len(base), len(values)))
    for group in groups:
        stepped = values.copy()
        stepped[group] += steps[group]
        change = residuals_of(stepped) - base
        for column, step in zip(group, stepped[group] - values[group], strict=True):
            derivatives[rows[column], column] = change[rows[column]] / step
    return derivatives


def jacobian(model: RigModel, observations: Observations, x: np.ndarray, free: np.ndarray,
             rows: list[np.ndarray] | None = None) -> np.ndarray:
    """Forward-difference Jacobian of the residuals in the free parameters, steps of 1e-6 of
    each parameter's scale (`rows`: `residual_rows` of the model and observations, computed
    here if not given)."""
    problem = FreeProblem.of(model, observations, x, free,
                             rows if rows is not None else residual_rows(model, observations))
    values = x[free]
    return forward_differences(problem.residuals, values, problem.residuals(values),
                               1e-6 * model.table.scales[free], problem.rows, problem.groups)


def uncertainty(jacobian_free: np.ndarray, scales: np.ndarray, chi2_per_dof: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One-sigma uncertainties of the free parameters and their covariance (natural units,
    scaled by χ²/dof when above 1), and the Jacobian's singular values in the parameters'
    scales."""
    scaled = jacobian_free * scales
    _, singular, rows = np.linalg.svd(scaled, full_matrices=False)
    # A direction the data do not constrain at all has an unbounded variance (a pseudo-
    # inverse would call it zero).
    inverse = np.where(singular > NULL_SINGULAR * singular[0], singular, 1e-30) ** -2.0
    covariance = (rows.T * inverse) @ rows * max(chi2_per_dof, 1.0) * np.outer(scales, scales)
    return np.sqrt(np.diag(covariance)), covariance, singular


def at_reference_spots(jacobian_free: np.ndarray, prior_rows: int, to_reference: float
                       ) -> np.ndarray:
    """The whitened Jacobian as it would be with every spot's and line pixel's σ times
    `to_reference` (its rows before the last `prior_rows`, the declared tolerances', divided
    by it): for judging what the data determine at DETERMINATION_SPOT_SIGMA_PX."""
    data_rows = jacobian_free.shape[0] - prior_rows
    return np.concatenate([jacobian_free[:data_rows] / to_reference,
                           jacobian_free[data_rows:]])


def least_determined(table: ParameterTable, free: np.ndarray, sigmas: np.ndarray) -> int | None:
    """The free parameter without a prior furthest beyond its limit (its index), or None if
    every one is determined. A parameter with a declared tolerance is always determined."""
    index = np.flatnonzero(free)
    ratio = sigmas / table.limits[index]
    ratio[np.isfinite(table.prior_sigmas[index])] = 0.0
    if not (ratio > 1).any():
        return None
    return int(index[int(np.argmax(ratio))])


def self_calibrate(rig: Rig, laser_ids: list[int], surfaces: list[KnownSurface],
                   diode: np.ndarray, frame: np.ndarray, pixels: np.ndarray,
                   covariance_px2: np.ndarray, fit_emitters: bool = False,
                   fit_camera: bool = True, line: LineObservations | None = None,
                   line_plane: tuple[np.ndarray, np.ndarray] | None = None) -> SelfCalibration:
    """Fit camera pose, beams, uncertain emitters and surfaces, and with `line` the line
    laser's plane (started at `line_plane`: normal, point [mm]), to spots and line pixels on
    known surfaces.

    `diode` indexes `laser_ids` and `frame` indexes `surfaces` for each spot (`pixels` N×2,
    `covariance_px2` N×2×2). Undetermined parameters without a prior are fixed one by one (the
    least determined first) until every fitted one is within its limit.
    """
    model = RigModel(rig, laser_ids, surfaces, fit_emitters, line, line_plane)
    observations = Observations(
        diode, frame, pixels, spot_whitening(covariance_px2),
        np.maximum(line.sigma_px, SIGMA_FLOOR_PX) if line is not None else np.empty(0))
    table = model.table
    scales = table.scales
    free = np.ones(model.size, bool)
    if not fit_camera:
        free[:6] = False
    fixed: dict[str, str] = {}
    x = np.zeros(model.size)
    rows = residual_rows(model, observations)   # whichever parameters are free
    # σ at the spots' own σ → σ at DETERMINATION_SPOT_SIGMA_PX (a parameter's σ scales with
    # the spots'), for judging what the data determine.
    spot_sigma_px = np.sqrt(np.trace(np.asarray(covariance_px2), axis1=1, axis2=2) / 2)
    to_reference = DETERMINATION_SPOT_SIGMA_PX / max(float(np.median(spot_sigma_px)),
                                                     SIGMA_FLOOR_PX) if len(pixels) else 1.0
    # What the data cannot determine is fixed before solving (linearised at the rig file):
    # left free, the solver runs off along those directions.
    prior_rows = len(model.prior_parameters)
    while (worst := least_determined(table, free, uncertainty(at_reference_spots(
            jacobian(model, observations, x, free, rows), prior_rows, to_reference),
            scales[free], 1.0)[0])) is not None:
        free[worst] = False
        fixed[table.names[worst]] = table.parameters[worst].advice
    while True:
        problem = FreeProblem.of(model, observations, x, free, rows)
        solution = least_squares(
            problem.residuals, x[free], jac=problem.solver_jacobian,
            x_scale=scales[free], method="trf", xtol=1e-12, ftol=1e-12, gtol=1e-12)
        x = problem.with_values(solution.x)
        dof = max(len(solution.fun) - int(free.sum()), 1)
        chi2 = float(np.sum(solution.fun**2))
        sigmas, covariance, singular = uncertainty(solution.jac, scales[free], chi2 / dof)
        worst = least_determined(table, free, uncertainty(at_reference_spots(
            solution.jac, prior_rows, to_reference), scales[free], 1.0)[0])
        if worst is None:
            break
        free[worst] = False
        fixed[table.names[worst]] = table.parameters[worst].advice
        x = np.zeros(model.size)
    all_sigmas = np.full(model.size, np.nan)
    all_sigmas[free] = sigmas
    all_covariance = np.full((model.size, model.size), np.nan)
    all_covariance[np.ix_(free, free)] = covariance
    spot_residuals = pixels - model.predict(x, diode, frame)
    # A surface with a declared reading σ is not a goal of the calibration, only its means.
    weak = {p.name: p.advice for p, sigma in zip(table.parameters, all_sigmas, strict=True)
            if p.kind not in (SURFACE_TILT_KIND, SURFACE_OFFSET_KIND) and sigma > p.kind.goal}
    return SelfCalibration(
        rig=model.to_rig(x), table=table, values=x, sigmas=all_sigmas,
        covariance=all_covariance, fixed=fixed, weak=weak,
        condition_number=float(singular[0] / max(singular[-1], 1e-300)),
        rms_px=float(np.sqrt(np.nanmean(np.sum(spot_residuals**2, axis=1)))),
        chi2=chi2, dof=dof, spot_residuals_px=spot_residuals,
        spot_residuals_sigma=np.linalg.norm(
            np.einsum("nij,nj->ni", observations.whitening, spot_residuals), axis=1),
        line_residuals_px=model.line_residuals(x) if line is not None else np.empty(0),
        surfaces=model.surfaces_at(x), model=model)


@dataclass(frozen=True)
class FreeProblem:
    """The residuals as a function of the free parameters, the others held at `x`, and
    which residual rows each free parameter moves."""

    model: RigModel
    observations: Observations
    x: np.ndarray                   # every parameter; the free ones are replaced
    free: np.ndarray                # bool, per parameter
    rows: list[np.ndarray]          # per free parameter (`residual_rows`)
    groups: list[np.ndarray]        # of free parameters (`column_groups`)

    @classmethod
    def of(cls, model: RigModel, observations: Observations, x: np.ndarray, free: np.ndarray,
           rows: list[np.ndarray]) -> FreeProblem:
        """The problem in the free parameters of `free` (`rows`: every parameter's
        `residual_rows`)."""
        free_rows = [r for r, is_free in zip(rows, free, strict=True) if is_free]
        return cls(model, observations, x, free, free_rows, column_groups(free_rows))

    def with_values(self, values: np.ndarray) -> np.ndarray:
        """The full parameter vector with the free ones at `values` (a new vector)."""
        full = self.x.copy()
        full[self.free] = values
        return full

    def residuals(self, values: np.ndarray) -> np.ndarray:
        """Every whitened residual with the free parameters at `values`."""
        return residuals(self.model, self.observations, self.with_values(values))

    def solver_jacobian(self, values: np.ndarray) -> np.ndarray:
        """The Jacobian least_squares' own 2-point scheme would give (its relative step
        √ε·max(1, |v|)), by groups of columns."""
        steps = np.sqrt(np.finfo(float).eps) * np.where(values >= 0, 1.0, -1.0) \
            * np.maximum(1.0, np.abs(values))
        return forward_differences(self.residuals, values, self.residuals(values), steps,
                                   self.rows, self.groups)
