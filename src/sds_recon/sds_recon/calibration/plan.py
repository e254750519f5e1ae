"""Plan the calibration protocol from the joint fit's own model: which known surfaces bring the
rig's parameters, and the tilts and heights it will measure, under their goal σ.

For a candidate set of known surfaces the planner predicts every spot of the rig file's rig
(each with the spot σ of discovery), linearises the joint fit there (`self_calibration`: the
same parameter table, priors and residuals) and takes the posterior covariance. It propagates
that to the reconstruction of unseen surfaces (a tilt series about the diagonal, an axis no
protocol uses): how far each tilt and height moves when the calibrated rig is off by one
posterior σ in any direction. Starting from a base protocol it adds, one at a time, the
candidate surface that brings an unmet goal (tilt or height) closest to it, until the goals are
met or no candidate pays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sds_model.rig import Rig

from sds_recon.calibration.lasers import KnownSurface
from sds_recon.calibration.parameters import (
    BEAM_KIND,
    CAMERA_POSITION_KIND,
    CAMERA_ROTATION_KIND,
    EMITTER_KIND,
    LINE_OFFSET_KIND,
    LINE_PLANE_KIND,
    SURFACE_OFFSET_KIND,
    SURFACE_TILT_KIND,
    Parameter,
    ParameterTable,
)
from sds_recon.calibration.rig_model import RigModel
from sds_recon.calibration.self_calibration import Observations, jacobian, spot_whitening
from sds_recon.reconstruction import reconstruct_spots
from sds_recon.surface_fit import fit_plane

SPOT_SIGMA_PX = 0.1
"""A spot's σ in each direction [px] for the prediction (discovery's, off the laser line)."""
TILT_GOAL_DEG = 0.033
"""Predicted one-σ tilt of an unseen surface the plan aims at (a third of 0.1°)."""
HEIGHT_GOAL_MM = 0.033
"""Predicted one-σ height error of an unseen surface's points the plan aims at."""
UNSEEN_TILTS_DEG = (10.0, 20.0, 35.0)
"""Tilts about the diagonal X = Y of the unseen surfaces the prediction is made for."""
LEAST_GAIN = 0.1
"""A surface is added only if it lowers the predicted σ of an unmet goal (tilt or height) by
this share or more: past that, more images cost the user time and buy nothing (the emitters'
and the readings' tolerances set the floor)."""


@dataclass(frozen=True)
class Prediction:
    """A protocol's predicted outcome: every parameter's posterior σ and covariance (natural
    units) and the one-σ tilt [deg] and height RMS [mm] errors on each unseen surface."""

    surfaces: list[KnownSurface]
    table: ParameterTable
    sigmas: np.ndarray
    tilt_sigma_deg: np.ndarray
    height_sigma_mm: np.ndarray
    covariance: np.ndarray            # posterior of every parameter (natural units)
    worst_tilt_gradient: np.ndarray   # the worst unseen tilt's change per parameter [rad]

    @property
    def names(self) -> list[str]:
        """Every parameter's name, in the order of `sigmas`."""
        return self.table.names

    @property
    def worst_tilt_deg(self) -> float:
        """The largest predicted tilt σ over the unseen surfaces [deg]."""
        return float(np.max(self.tilt_sigma_deg))

    @property
    def worst_height_mm(self) -> float:
        """The largest predicted height σ over the unseen surfaces [mm]."""
        return float(np.max(self.height_sigma_mm))

    @property
    def tilt_met(self) -> bool:
        """Whether tilts of unseen surfaces are predicted within TILT_GOAL_DEG."""
        return self.worst_tilt_deg <= TILT_GOAL_DEG

    @property
    def height_met(self) -> bool:
        """Whether heights of unseen surfaces are predicted within HEIGHT_GOAL_MM."""
        return self.worst_height_mm <= HEIGHT_GOAL_MM

    def meets_goals(self) -> bool:
        """Whether tilts and heights of unseen surfaces are predicted within their goals."""
        return self.tilt_met and self.height_met

    def gain_over(self, before: Prediction) -> float:
        """The largest share by which this prediction lowers the σ of a goal that `before`
        does not meet (tilt or height; 0 if it lowers none)."""
        gains = [0.0]
        if not before.tilt_met:
            gains.append(1.0 - self.worst_tilt_deg / before.worst_tilt_deg)
        if not before.height_met:
            gains.append(1.0 - self.worst_height_mm / before.worst_height_mm)
        return max(gains)


def unseen_reach_mm(rig: Rig) -> float:
    """How far above and below the fill level the steepest unseen surface reaches at the
    container's wall [mm]: the heights the calibrated rig must measure."""
    return float(rig.container.radius_mm * np.tan(np.radians(max(UNSEEN_TILTS_DEG))))


def diagonal(tilt_deg: float) -> KnownSurface:
    """A surface tilted by `tilt_deg` about the diagonal X = Y."""
    slope = float(np.arctan(np.tan(np.radians(tilt_deg)) / np.sqrt(2.0)))
    return KnownSurface(0.0, slope, slope)


def _visible_spots(rig: Rig, surfaces: list[KnownSurface]
                   ) -> tuple[list[int], np.ndarray, np.ndarray, np.ndarray]:
    """Every tracked diode's predicted spot on each surface inside the container: laser ids,
    diode and frame indices, pixels."""
    ids = [d.laser_id for d in rig.tracked_diodes]
    model = RigModel(rig, ids, surfaces)
    diode, frame = (a.ravel() for a in np.meshgrid(np.arange(len(ids)),
                                                   np.arange(len(surfaces)), indexing="ij"))
    x = np.zeros(model.size)
    pixels = model.predict(x, diode, frame)
    hits = model.hits(x, diode, frame)
    inside = np.isfinite(pixels).all(axis=1) & (np.hypot(hits[:, 0], hits[:, 1])
                                                < rig.container.radius_mm)
    return ids, diode[inside], frame[inside], pixels[inside]


def _surface_of(rig: Rig, ids: list[int], pixels: np.ndarray) -> tuple[float, float, np.ndarray]:
    """The plane through the spots at `pixels` reconstructed with `rig`: tilts [rad], heights."""
    points = reconstruct_spots(rig, ids, pixels, np.full(len(ids), SPOT_SIGMA_PX), 1.0)
    plane = fit_plane(points.points_mm)
    return plane.tilt_x_rad, plane.tilt_y_rad, points.points_mm[:, 2]


@dataclass(frozen=True)
class UnseenSensitivity:
    """How the reconstruction of each unseen diagonal surface moves per unit of each of the
    rig's parameters (named as in every fit's table; the known surfaces' own parameters do
    not move it): its two tilts [rad] and its points' heights [mm]."""

    names: list[str]
    tilt_gradients: list[np.ndarray]     # one per unseen surface: parameters × 2
    height_gradients: list[np.ndarray]   # one per unseen surface: parameters × points

    def rows(self, names: list[str], unseen: int) -> tuple[np.ndarray, np.ndarray]:
        """The gradients of unseen surface `unseen` in the order of `names` (zero for a
        parameter that is not the rig's)."""
        index = {name: k for k, name in enumerate(self.names)}
        tilt, height = self.tilt_gradients[unseen], self.height_gradients[unseen]
        tilt_rows, height_rows = np.zeros((len(names), 2)), np.zeros((len(names),
                                                                       height.shape[1]))
        for row, name in enumerate(names):
            if name in index:
                tilt_rows[row], height_rows[row] = tilt[index[name]], height[index[name]]
        return tilt_rows, height_rows


def unseen_sensitivity(rig: Rig) -> UnseenSensitivity:
    """The unseen diagonal surfaces' sensitivity to the rig's parameters, by differences of
    1e-3 of each parameter's scale (the same for every protocol: computed once per plan)."""
    ids = [d.laser_id for d in rig.tracked_diodes]
    model = RigModel(rig, ids, [])
    scales = model.table.scales
    tilt_gradients, height_gradients = [], []
    for tilt_deg in UNSEEN_TILTS_DEG:
        seen_ids, _, _, seen_px = _visible_spots(rig, [diagonal(tilt_deg)])
        base_x, base_y, base_heights = _surface_of(rig, seen_ids, seen_px)
        base = np.array([base_x, base_y])
        tilt_rows, height_rows = [], []
        for k in range(model.size):
            step = np.zeros(model.size)
            step[k] = 1e-3 * scales[k]
            tilt_x, tilt_y, heights = _surface_of(model.to_rig(step), seen_ids, seen_px)
            tilt_rows.append((np.array([tilt_x, tilt_y]) - base) / step[k])
            height_rows.append((heights - base_heights) / step[k])
        tilt_gradients.append(np.array(tilt_rows))
        height_gradients.append(np.array(height_rows))
    return UnseenSensitivity(model.table.names, tilt_gradients, height_gradients)


def unseen_tilt_sigmas_deg(sensitivity: UnseenSensitivity, names: list[str],
                           covariance: np.ndarray) -> np.ndarray:
    """σ of each unseen diagonal surface's two tilts [deg] (UNSEEN_TILTS_DEG × 2) that the
    parameters `names` with `covariance` give (a fit's own, or a plan's: NaN, a parameter
    held fixed, counts as known)."""
    known = np.nan_to_num(covariance)
    sigmas = []
    for unseen in range(len(UNSEEN_TILTS_DEG)):
        gradient, _ = sensitivity.rows(names, unseen)
        sigmas.append(np.degrees(np.sqrt(np.einsum("ki,kl,li->i", gradient, known,
                                                   gradient))))
    return np.array(sigmas)


def unseen_height_sigmas_mm(sensitivity: UnseenSensitivity, names: list[str],
                            covariance: np.ndarray) -> np.ndarray:
    """RMS over its points of each unseen diagonal surface's height σ [mm] (one per
    UNSEEN_TILTS_DEG) that the parameters `names` with `covariance` give (NaN, a parameter
    held fixed, counts as known)."""
    known = np.nan_to_num(covariance)
    sigmas = []
    for unseen in range(len(UNSEEN_TILTS_DEG)):
        _, gradient = sensitivity.rows(names, unseen)
        sigmas.append(np.sqrt(np.mean(np.einsum("ki,kl,li->i", gradient, known, gradient))))
    return np.array(sigmas)


def predict(rig: Rig, surfaces: list[KnownSurface],
            sensitivity: UnseenSensitivity | None = None,
            spot_sigma_px: float = SPOT_SIGMA_PX) -> Prediction:
    """The posterior σ of every parameter after calibrating `rig` (its tolerances as priors)
    on `surfaces` whose spots are measured to `spot_sigma_px` in each direction, and the σ of
    tilt and heights it gives unseen diagonal surfaces (`sensitivity`:
    `unseen_sensitivity(rig)`, computed here if not given)."""
    sensitivity = sensitivity or unseen_sensitivity(rig)
    ids, diode, frame, pixels = _visible_spots(rig, surfaces)
    model = RigModel(rig, ids, surfaces)
    covariance = np.full((len(pixels), 1, 1), spot_sigma_px**2) * np.eye(2)
    observations = Observations(diode, frame, pixels, spot_whitening(covariance), np.empty(0))
    free = np.ones(model.size, bool)
    x = np.zeros(model.size)
    design = jacobian(model, observations, x, free)
    scales = model.table.scales
    information = (design * scales).T @ (design * scales)
    posterior = np.linalg.pinv(information, rcond=1e-12) * np.outer(scales, scales)
    sigmas = np.sqrt(np.clip(np.diag(posterior), 0.0, None))
    tilt_sigmas = unseen_tilt_sigmas_deg(sensitivity, model.table.names, posterior)
    height_sigma = unseen_height_sigmas_mm(sensitivity, model.table.names, posterior)
    worst_unseen, worst_axis = np.unravel_index(int(np.argmax(tilt_sigmas)), tilt_sigmas.shape)
    worst_gradient = sensitivity.rows(model.table.names, int(worst_unseen))[0][:, worst_axis]
    return Prediction(list(surfaces), model.table, sigmas, tilt_sigmas.max(axis=1),
                      height_sigma, posterior, worst_gradient)


GROUP_OF_KIND = {BEAM_KIND: "beams' leans", EMITTER_KIND: "emitters' places",
                 SURFACE_TILT_KIND: "surfaces' tilt readings", SURFACE_OFFSET_KIND: "fill levels",
                 LINE_PLANE_KIND: "line plane", LINE_OFFSET_KIND: "line plane"}
"""The group each kind of parameter counts in when the planner says what sets the unseen
tilt (the camera's pose parameters count alone; the camera file's intrinsics, each of a kind
of its own, together)."""


def parameter_group(parameter: Parameter) -> str:
    """The group `parameter` counts in when the planner says what sets the unseen tilt."""
    if parameter.kind in (CAMERA_ROTATION_KIND, CAMERA_POSITION_KIND):
        return parameter.name
    return GROUP_OF_KIND.get(parameter.kind, "camera file")


def tilt_shares(prediction: Prediction) -> list[tuple[str, float]]:
    """What sets the worst unseen tilt's σ: for each parameter group (`parameter_group`), the
    share of its variance that would go were the group known exactly (the posterior
    conditioned on it), largest first. Shares overlap: groups that move together (the
    camera's turn about the vertical and the emitters' layout) each claim what they share."""
    covariance, gradient = prediction.covariance, prediction.worst_tilt_gradient
    total = float(gradient @ covariance @ gradient)
    groups = np.array([parameter_group(p) for p in prediction.table.parameters])
    shares = []
    for group in dict.fromkeys(groups):
        known, rest = groups == group, groups != group
        conditioned = covariance[np.ix_(rest, rest)] - covariance[np.ix_(rest, known)] @ \
            np.linalg.pinv(covariance[np.ix_(known, known)]) @ covariance[np.ix_(known, rest)]
        left = float(gradient[rest] @ conditioned @ gradient[rest])
        shares.append((str(group), 1.0 - left / total))
    return sorted(shares, key=lambda share: -share[1])


def plan(rig: Rig, base: list[KnownSurface], candidates: list[KnownSurface]
         ) -> list[Prediction]:
    """Greedy plan: the prediction for `base`, then for base plus each next candidate that
    lowers the σ of an unmet goal by the largest share (`Prediction.gain_over`), until the
    goals are met, the candidates run out, or the best gains less than LEAST_GAIN. Returns
    every step's prediction, the last the plan."""
    chosen = list(base)
    sensitivity = unseen_sensitivity(rig)
    steps = [predict(rig, chosen, sensitivity)]
    left = list(candidates)
    while left and not steps[-1].meets_goals():
        trials = [predict(rig, [*chosen, candidate], sensitivity) for candidate in left]
        gains = [trial.gain_over(steps[-1]) for trial in trials]
        best = int(np.argmax(gains))
        if gains[best] < LEAST_GAIN:
            break
        chosen.append(left.pop(best))
        steps.append(trials[best])
    return steps
