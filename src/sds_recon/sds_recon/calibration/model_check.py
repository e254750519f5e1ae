"""Is the rig model believed? χ² of the joint fit against its spread, and where a misfit sits.

With the model right and every σ honest, χ² follows a χ² distribution with the fit's degrees
of freedom: χ²/dof within [q(0.0013), q(0.9987)] / dof (three σ each side) in 99.7 % of
calibrations. The spots' σ are themselves estimates (from the pixels' noise), good to
SPOT_SIGMA_ACCURACY, which widens the range by that factor squared on each side. A declared
tolerance the data push a parameter beyond by PULL_FAIL of its σ is a conflict of its own (a
few tight priors among many residuals hardly move χ²). Beyond either the model does not
explain the data: the check names the surfaces and diodes whose spots fit worst and the
declared tolerances the fit had to exceed (a parameter moved by more than PULL_LIMIT of its
prior σ), and says what most likely happened.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2 as chi2_distribution

from sds_recon.calibration.parameters import (
    EMITTER_KIND,
    SURFACE_OFFSET_KIND,
    SURFACE_TILT_KIND,
)
from sds_recon.calibration.self_calibration import SelfCalibration

TAIL = 0.00135
"""Probability in each tail outside the expected range (three σ of a normal)."""
SPOT_SIGMA_ACCURACY = 0.1
"""How well the spots' σ are known (a share): with the right model, rendered rigs gave
χ²/dof from 0.84 to 1.07 (spots' σ 4 % large on average), beyond the spread of χ² alone."""
PULL_LIMIT = 3.0
"""A parameter moved by more than this many σ of its declared tolerance is named."""
PULL_FAIL = 5.0
"""A parameter moved by more than this many σ of its declared tolerance fails the check: with
honest tolerances that happens once in 10⁵–10⁶ calibrations of 40 such parameters."""
WORST_SHOWN = 3
"""Surfaces, diodes and parameters named at most, each."""


@dataclass(frozen=True)
class ModelCheck:
    """χ²/dof, its expected range, and, when outside it, where the misfit sits and why."""

    chi2_per_dof: float
    dof: int
    expected: tuple[float, float]
    explained: bool
    surfaces: list[tuple[int, float]]     # (frame, RMS residual in σ) of the worst surfaces
    diodes: list[tuple[int, float]]       # (laser id, RMS residual in σ) of the worst diodes
    pulled: list[tuple[str, float]]       # (parameter, change in σ of its tolerance)
    likely_cause: str

    def summary(self) -> str:
        """One line: the check's verdict, and where and why when the model fails."""
        low, high = self.expected
        verdict = (f"chi2/dof {self.chi2_per_dof:.3g} within its expected {low:.3g}-{high:.3g} "
                   f"({self.dof} degrees of freedom, spots' sigma to "
                   f"{SPOT_SIGMA_ACCURACY:.0%}), no declared tolerance exceeded by "
                   f"{PULL_FAIL:g} sigma")
        if self.explained:
            return f"model check: {verdict}"
        where = "; ".join(part for part in (
            "worst surfaces " + ", ".join(f"{f} ({s:.1f} sigma)" for f, s in self.surfaces)
            if self.surfaces else "",
            "worst diodes " + ", ".join(f"{i} ({s:.1f} sigma)" for i, s in self.diodes)
            if self.diodes else "",
            "beyond their tolerance " + ", ".join(f"{n} ({p:+.1f} sigma)"
                                                  for n, p in self.pulled)
            if self.pulled else "") if part)
        return (f"THE MODEL DOES NOT EXPLAIN THE DATA: chi2/dof {self.chi2_per_dof:.3g} "
                f"(expected {low:.3g}-{high:.3g}, {self.dof} degrees of freedom); {where}; "
                f"likely cause: {self.likely_cause}")


def expected_range(dof: int) -> tuple[float, float]:
    """χ²/dof's range for `dof` degrees of freedom (TAIL outside it on each side), widened by
    the spots' σ being known to SPOT_SIGMA_ACCURACY."""
    return (float(chi2_distribution.ppf(TAIL, dof) / dof) * (1 - SPOT_SIGMA_ACCURACY) ** 2,
            float(chi2_distribution.ppf(1 - TAIL, dof) / dof) * (1 + SPOT_SIGMA_ACCURACY) ** 2)


def _rms_by(groups: np.ndarray, in_sigma: np.ndarray) -> dict[int, float]:
    """RMS of the residuals [σ per axis] of each group."""
    return {int(g): float(np.sqrt(np.mean(in_sigma[groups == g] ** 2) / 2))
            for g in np.unique(groups)}


def check_model(fit: SelfCalibration, laser_ids: list[int], diode: np.ndarray,
                frame: np.ndarray) -> ModelCheck:
    """The joint fit's χ²/dof against its expected range; where the misfit sits and the
    likely cause when outside it. `diode` (index into `laser_ids`) and `frame` per spot."""
    low, high = expected_range(fit.dof)
    ratio = fit.chi2_per_dof
    explained = low <= ratio <= high
    in_sigma = fit.spot_residuals_sigma
    by_surface = _rms_by(frame, in_sigma)
    by_diode = {laser_ids[k]: rms for k, rms in _rms_by(diode, in_sigma).items()}
    pulls = fit.pulls()
    order = np.argsort(-np.nan_to_num(np.abs(pulls)))
    pulled = [(fit.names[k], float(pulls[k])) for k in order[:WORST_SHOWN]
              if np.abs(pulls[k]) > PULL_LIMIT]
    explained = explained and not np.any(np.abs(np.nan_to_num(pulls)) > PULL_FAIL)
    if explained:
        return ModelCheck(ratio, fit.dof, (low, high), True, [], [], pulled, "")
    overall = float(np.sqrt(np.mean(in_sigma**2) / 2))
    worst_surfaces = sorted(by_surface.items(), key=lambda item: -item[1])[:WORST_SHOWN]
    worst_diodes = sorted(by_diode.items(), key=lambda item: -item[1])[:WORST_SHOWN]
    return ModelCheck(ratio, fit.dof, (low, high), False,
                      [s for s in worst_surfaces if s[1] > overall],
                      [d for d in worst_diodes if d[1] > overall], pulled,
                      _likely_cause(fit, by_surface, by_diode, pulled, ratio >= low))


def _likely_cause(fit: SelfCalibration, by_surface: dict[int, float],
                  by_diode: dict[int, float], pulled: list[tuple[str, float]],
                  misfit: bool) -> str:
    """What most likely made the model fail (`misfit`: the data fit worse than their σ, or a
    tolerance is exceeded; else they fit better), in words."""
    if not misfit:
        return "the spots' σ are smaller than declared (or too few data for the fit)"
    kinds = {fit.table.parameters[fit.table.index(name)].kind for name, _ in pulled}
    if SURFACE_TILT_KIND in kinds or SURFACE_OFFSET_KIND in kinds:
        return ("a tolerance declared too tight: the tilt table's or fill level's accuracy "
                "(tilt_sigma_deg or tilt_x/y_sigma_deg, offset_sigma_mm), or a misread table "
                "angle")
    if EMITTER_KIND in kinds:
        return "an emitter's tolerance declared too tight, or a moved emitter"
    if pulled:
        return f"a tolerance declared too tight ({pulled[0][0]})"
    surfaces, diodes = sorted(by_surface.values()), sorted(by_diode.values())
    if len(surfaces) > 1 and surfaces[-1] > 3 * surfaces[len(surfaces) // 2]:
        return "one surface's reading is off: a misread table angle or fill level"
    if len(diodes) > 1 and diodes[-1] > 3 * diodes[len(diodes) // 2]:
        return "one diode does not follow its beam: a moved emitter or a wrong identity"
    return ("something the rig file declares exact is not: declare the tolerances of the "
            "emitters (tolerances.emitter_mm) and of the tilt table (tilt_sigma_deg)")
