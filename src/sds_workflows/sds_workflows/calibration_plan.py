"""`sds calibrate plan`: which known surfaces to record, planned from the joint fit's model.

The base is the seed's tilt table series (0–35° about X in 5° steps); the candidates are
tilts about Y and level surfaces at other fill levels, every 10 mm over the heights the
steepest unseen surface reaches inside the container (or a CSV of the user's own). Each
surface is declared with the accuracy the user can read it to: the table's angle, a spirit
level's on level frames, the fill level's. `sds_recon.calibration.plan` adds the candidates
that pay, and the planned protocol is written as the surfaces CSV `sds calibrate rig` reads.
"""

from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
from sds_model.rig import Rig
from sds_recon.calibration.laser_files import read_surfaces
from sds_recon.calibration.lasers import Accuracy, KnownSurface
from sds_recon.calibration.plan import (
    HEIGHT_GOAL_MM,
    LEAST_GAIN,
    SPOT_SIGMA_PX,
    TILT_GOAL_DEG,
    Prediction,
    plan,
    predict,
    tilt_shares,
    unseen_reach_mm,
    unseen_sensitivity,
)

from sds_workflows.rig_calibration import FRAMES_PER_STILL

SHOWN_SHARE = 0.1
"""A parameter group is named among what sets the unseen tilt when knowing it exactly would
take this share of the tilt's variance or more."""
BASE_TILTS_DEG = (0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0)
"""The seed's tilt table series about X (Table 3)."""
CANDIDATE_TILTS_DEG = (12.5, 22.5, 32.5)
"""Tilts about Y offered to the planner."""
LEVEL_STEP_MM = 10.0
"""Spacing of the other fill levels offered to the planner (level surfaces)."""
LEAST_DEPTH_MM = 10.0
"""Liquid left in the container at the lowest level offered (the spots must fall on liquid)."""
INCLINOMETER_DEG = (0.1, 0.05)
"""Tilted frames read to these σ (a digital inclinometer on the table) in the what-if lines."""
MEASURED_EMITTER_MM = 0.1
"""The emitters' σ in the what-if line for a holder measured after printing."""


def candidate_levels_mm(rig: Rig) -> list[float]:
    """Fill levels [mm from the first] to offer: every LEVEL_STEP_MM up to the height the
    steepest unseen surface reaches at the wall (rounded up to a step), either way, leaving
    LEAST_DEPTH_MM of liquid and not above the container's rim. Beams calibrated over the
    heights they will measure need no extrapolation."""
    container = rig.container
    steps = int(np.ceil(unseen_reach_mm(rig) / LEVEL_STEP_MM))
    levels = [k * LEVEL_STEP_MM for k in range(-steps, steps + 1) if k != 0]
    return [level for level in levels
            if container.fill_height_mm + level >= LEAST_DEPTH_MM
            and container.fill_height_mm + level <= container.height_mm]


def default_surfaces(rig: Rig, accuracy: Accuracy
                     ) -> tuple[list[KnownSurface], list[KnownSurface]]:
    """The base series and the candidates for `rig`, declared with `accuracy`."""
    base = [KnownSurface(0.0, float(np.radians(a)), 0.0) for a in BASE_TILTS_DEG]
    candidates = ([KnownSurface(0.0, 0.0, float(np.radians(a))) for a in CANDIDATE_TILTS_DEG]
                  + [KnownSurface(level, 0.0, 0.0) for level in candidate_levels_mm(rig)])
    return [accuracy.declare(s) for s in base], [accuracy.declare(s) for s in candidates]


def plan_protocol(rig: Rig, accuracy: Accuracy, candidates_csv: Path | None = None
                  ) -> list[Prediction]:
    """The planner's steps for `rig` (its tolerances as priors): the base series, then each
    surface added; the last step is the plan. `candidates_csv` (a surfaces CSV; σ columns
    absent: `accuracy`'s) replaces the default candidates."""
    base, candidates = default_surfaces(rig, accuracy)
    if candidates_csv is not None:
        candidates = [s if s.has_sigma else accuracy.declare(s)
                      for _, s in sorted(read_surfaces(candidates_csv).items())]
    return plan(rig, base, candidates)


def what_would_meet_the_goals(rig: Rig, accuracy: Accuracy, planned: Prediction
                              ) -> list[tuple[str, Prediction]]:
    """The planned surfaces' prediction under better knowledge, one change at a time: the
    tilted frames read with an inclinometer, the emitters measured, the protocol recorded
    twice (two readings of every surface, their errors independent), each surface's spots
    averaged over FRAMES_PER_STILL frames (speckle new in each: σ over √n)."""
    sensitivity = unseen_sensitivity(rig)
    whatif = []
    for sigma_deg in INCLINOMETER_DEG:
        better = accuracy.with_inclinometer(sigma_deg)
        whatif.append((f"tilted frames read to {sigma_deg:g} deg (an inclinometer)",
                       predict(rig, [better.declare(s) for s in planned.surfaces],
                               sensitivity)))
    emitter_mm = rig.tolerances.emitter_mm
    if emitter_mm is not None and emitter_mm > MEASURED_EMITTER_MM:
        measured = replace(rig, tolerances=replace(rig.tolerances,
                                                   emitter_mm=MEASURED_EMITTER_MM))
        whatif.append((f"emitters known to {MEASURED_EMITTER_MM:g} mm (measured holder)",
                       predict(measured, planned.surfaces, unseen_sensitivity(measured))))
    whatif.append(("every surface recorded twice",
                   predict(rig, [*planned.surfaces, *planned.surfaces], sensitivity)))
    # Speckle on the liquid is new in every frame: the frames of a still average it down.
    averaged_px = SPOT_SIGMA_PX / np.sqrt(FRAMES_PER_STILL)
    whatif.append((f"{FRAMES_PER_STILL} frames of each surface (spots to {averaged_px:.3f} px)",
                   predict(rig, planned.surfaces, sensitivity, averaged_px)))
    return whatif


def what_if_text(whatif: list[tuple[str, Prediction]]) -> str:
    """The what-if predictions as a table beside the plan's."""
    lines = ["the planned protocol with better knowledge (one change at a time):"]
    for what, prediction in whatif:
        met = "  goals met" if prediction.meets_goals() else ""
        lines.append(_row(what, prediction) + met)
    return "\n".join(lines)


def _row(what: str, prediction: Prediction) -> str:
    """One line of the planner's tables: what was planned, and its predicted tilt σ [deg],
    height σ [mm] and camera height σ [mm]."""
    return (f"{what:<58} {prediction.worst_tilt_deg:>9.3f} {prediction.worst_height_mm:>10.3f} "
            f"{prediction.sigmas[prediction.names.index('camera Z')]:>12.3f}")


def _describe(surface: KnownSurface) -> str:
    """A surface in words: its tilts [deg] and fill level [mm]."""
    return (f"tilt x {np.degrees(surface.tilt_x_rad):5.1f} deg, y "
            f"{np.degrees(surface.tilt_y_rad):5.1f} deg, level {surface.offset_mm:+5.1f} mm")


def plan_text(steps: list[Prediction]) -> str:
    """The planner's steps as a table: what each added surface predicts for unseen surfaces."""
    base = len(steps[0].surfaces)
    lines = ["predicted one-sigma errors of unseen surfaces (tilts about the diagonal) and of "
             "the camera height:",
             f"{'protocol':<58} {'tilt deg':>9} {'height mm':>10} {'camera Z mm':>12}"]
    for index, step in enumerate(steps):
        what = f"the base series ({base} tilts about X)" if index == 0 else \
            "+ " + _describe(step.surfaces[-1])
        lines.append(_row(what, step))
    last = steps[-1]
    lines.append(_goals_line(last))
    return "\n".join(lines)


def _goals_line(planned: Prediction) -> str:
    """Which goals the plan meets and, if not all, why the planner stopped."""
    if planned.meets_goals():
        return "goals met"
    goals = [(f"tilt {TILT_GOAL_DEG:g} deg", planned.tilt_met),
             (f"height {HEIGHT_GOAL_MM:g} mm", planned.height_met)]
    unmet = [goal for goal, met in goals if not met]
    met = "".join(f" ({goal} met)" for goal, is_met in goals if is_met)
    noun, pronoun = ("goals", "them") if len(unmet) > 1 else ("goal", "it")
    return (f"{noun} {' and '.join(unmet)} not met{met}: no candidate lowers {pronoun} by "
            f"{LEAST_GAIN:.0%} more")


def shares_text(planned: Prediction) -> str:
    """What sets the planned protocol's unseen tilt σ: the parameter groups whose exact
    knowledge would take SHOWN_SHARE or more of its variance (`tilt_shares`)."""
    shares = [f"{group} {share:.0%}" for group, share in tilt_shares(planned)
              if share >= SHOWN_SHARE]
    return ("what sets the unseen tilt's sigma (the share of its variance that would go, each "
            "known exactly; they overlap): " + ", ".join(shares))


def write_protocol(prediction: Prediction, path: Path) -> None:
    """The planned surfaces as the surfaces CSV of `sds calibrate rig` (frame k = image k)."""
    with path.open("w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["frame", "tilt_x_deg", "tilt_y_deg", "offset_mm", "tilt_x_sigma_deg",
                         "tilt_y_sigma_deg", "offset_sigma_mm"])
        for frame, s in enumerate(prediction.surfaces):
            writer.writerow([frame, f"{np.degrees(s.tilt_x_rad):.6g}",
                             f"{np.degrees(s.tilt_y_rad):.6g}", f"{s.offset_mm:.6g}",
                             f"{np.degrees(s.tilt_x_sigma_rad):.6g}",
                             f"{np.degrees(s.tilt_y_sigma_rad):.6g}", f"{s.offset_sigma_mm:.6g}"])
