"""Calibration that holds on the rig as built: every tolerance a parameter with its prior, the
model checked against χ²'s spread (issue: the rig as built).

The true rigs here differ from their files as the seed's did: emitters off their drawn places
(σ 0.3 mm, a 3D-printed holder), a tilt table read to ±0.5° about its axis (σ 0.15° across
it), level frames to 0.05°, fill levels to 0.05 mm, the camera turned and moved, beams leaning
and, for the rendered rig, a camera file off by one Table 2 σ."""

from __future__ import annotations

import itertools
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from sds_model.geometry import RigidTransform
from sds_model.rig import RigError, Tolerances, load_rig, save_rig
from sds_recon.calibration.laser_files import read_surfaces
from sds_recon.calibration.lasers import Accuracy, KnownSurface
from sds_recon.calibration.model_check import check_model
from sds_recon.calibration.plan import (
    HEIGHT_GOAL_MM,
    plan,
    predict,
    tilt_shares,
    unseen_sensitivity,
    unseen_tilt_sigmas_deg,
)
from sds_recon.calibration.rig_calibration import calibrate_rig
from sds_recon.calibration.rig_model import LineObservations, RigModel
from sds_recon.calibration.self_calibration import (
    FreeProblem,
    Observations,
    SelfCalibration,
    jacobian,
    residual_rows,
    residuals,
    self_calibrate,
    spot_whitening,
)
from sds_sim.tilt_series import declared, true_surfaces
from sds_sim.true_rig import RigErrors, random_layout, true_rig
from sds_workflows.calibration_plan import (
    default_surfaces,
    plan_protocol,
    plan_text,
    what_would_meet_the_goals,
)
from sds_workflows.calibration_trial import SEED_READINGS, as_built_trial, protocol_readings

ROOT = Path(__file__).resolve().parents[1]
STELIUM = ROOT / "config" / "rigs" / "stelium.yaml"
SPOT_SIGMA_PX = 0.07
SDS = str(Path(sys.executable).with_name("sds"))


def _spots(true, surfaces: list[KnownSurface], rng: np.random.Generator,
           sigma_px: float = SPOT_SIGMA_PX):
    """Every diode's spot on every true surface with `sigma_px` of noise: ids, diode, frame,
    pixels, covariances."""
    ids = [d.laser_id for d in true.diodes]
    model = RigModel(true, ids, surfaces)
    diode, frame = (a.ravel() for a in np.meshgrid(np.arange(len(ids)),
                                                   np.arange(len(surfaces)), indexing="ij"))
    pixels = model.predict(np.zeros(model.size), diode, frame)
    hits = model.hits(np.zeros(model.size), diode, frame)
    seen = np.isfinite(pixels).all(axis=1) & (np.hypot(hits[:, 0], hits[:, 1]) < 55)
    noisy = pixels[seen] + rng.normal(0.0, sigma_px, (int(seen.sum()), 2))
    covariance = np.full((len(noisy), 1, 1), sigma_px**2) * np.eye(2)
    return ids, diode[seen], frame[seen], noisy, covariance


def _normalised_camera_and_surface_errors(fit: SelfCalibration, true,
                                          truths: list[KnownSurface]) -> np.ndarray:
    """The fit's camera and surface parameters' errors against the truth, each in its σ."""
    turn = Rotation.from_matrix(fit.rig.world_to_camera.rotation.T
                                @ true.world_to_camera.rotation).as_rotvec()
    shift = fit.rig.camera_position_mm - true.camera_position_mm
    errors = list(turn / fit.sigmas[:3]) + list(shift / fit.sigmas[3:6])
    for index, (fitted, truth) in enumerate(zip(fit.surfaces, truths, strict=True)):
        errors += [(fitted.tilt_x_rad - truth.tilt_x_rad) / fit.sigma_of(f"surface {index} tilt x"),
                   (fitted.tilt_y_rad - truth.tilt_y_rad) / fit.sigma_of(f"surface {index} tilt y")]
        if f"surface {index} offset" in fit.names:   # the other fill levels
            errors.append((fitted.offset_mm - truth.offset_mm)
                          / fit.sigma_of(f"surface {index} offset"))
    return np.array(errors)


def test_the_jacobian_by_groups_of_columns_is_the_one_of_each_column_alone() -> None:
    """Every kind of parameter (camera pose and intrinsics, beams, emitters, surfaces' angles
    and levels, the line plane, declared tolerances): stepping the columns that share no
    residual together gives the Jacobian that stepping each column alone gives, in a
    fraction of the residual evaluations."""
    rng = np.random.default_rng(5)
    designed = random_layout(load_rig(STELIUM), rng)
    rig = replace(designed, tolerances=Tolerances(emitter_mm=0.3, line_plane_deg=0.5))
    surfaces = declared(protocol_readings(), SEED_READINGS)
    surfaces[3] = replace(surfaces[3], tilt_y_sigma_rad=0.0)   # one angle read exactly
    ids, diode, frame, pixels, covariance = _spots(rig, surfaces, rng)
    line_count = 300
    line = LineObservations(rng.integers(0, len(surfaces), line_count),
                            rng.uniform([1700.0, 800.0], [2100.0, 1300.0], (line_count, 2)),
                            np.full(line_count, 0.1))
    assert rig.line_laser is not None
    model = RigModel(rig, ids, surfaces, line=line,
                     line_plane=(rig.line_laser.normal, rig.line_laser.emitter_mm))
    kinds = {p.kind.name.split()[0] for p in model.table.parameters}
    assert {"camera", "beam", "emitter", "surface", "line"} <= kinds
    assert "surface 3 tilt x" in model.table.names and "surface 3 tilt y" not in \
        model.table.names
    observations = Observations(diode, frame, pixels, spot_whitening(covariance), line.sigma_px)
    x = rng.normal(0.0, 0.2, model.size) * model.table.scales
    free = np.ones(model.size, bool)
    free[rng.choice(model.size, 5, replace=False)] = False
    base = residuals(model, observations, x)
    alone = []
    for k in np.flatnonzero(free):
        stepped = x.copy()
        stepped[k] += 1e-6 * model.table.scales[k]
        alone.append((residuals(model, observations, stepped) - base) / (stepped[k] - x[k]))
    np.testing.assert_allclose(jacobian(model, observations, x, free), np.column_stack(alone),
                               rtol=1e-9, atol=1e-12)
    groups = FreeProblem.of(model, observations, x, free,
                            residual_rows(model, observations)).groups
    assert len(groups) < free.sum() / 4, (len(groups), free.sum())


@pytest.mark.parametrize("seed", [11, 12])
def test_declared_tolerances_explain_the_data_and_their_sigma_hold_the_truth(seed: int) -> None:
    """Spots with exactly known noise: with the tolerances declared, χ²/dof is within its
    range and the σ hold the truth; declared ten times too tight, or left out (today's
    model), the check says the model does not explain the data, and why."""
    rng = np.random.default_rng(seed)
    designed = random_layout(load_rig(STELIUM), rng)
    true = true_rig(designed, RigErrors(emitter_sigma_mm=0.3), rng)
    readings = protocol_readings()
    truths = true_surfaces(readings, SEED_READINGS, rng)
    ids, diode, frame, pixels, covariance = _spots(true, truths, rng)
    nominal = replace(designed, tolerances=Tolerances(emitter_mm=0.3))

    def fit(rig, surfaces):
        result = self_calibrate(rig, ids, surfaces, diode, frame, pixels, covariance)
        return result, check_model(result, ids, diode, frame)

    right, right_check = fit(nominal, declared(readings, SEED_READINGS))
    assert right_check.explained, right_check.summary()
    assert not right.fixed
    normalised = _normalised_camera_and_surface_errors(right, true, truths)
    assert np.sqrt(np.mean(normalised**2)) < 1.5 and np.max(np.abs(normalised)) < 4.5
    beams = [np.degrees(np.arccos(np.clip(right.rig.diode(i).direction
                                          @ true.diode(i).direction, -1, 1))) for i in ids]
    assert max(beams) < 0.1

    _, tight_check = fit(nominal, declared(readings, SEED_READINGS, factor=0.1))
    assert not tight_check.explained
    assert "THE MODEL DOES NOT EXPLAIN THE DATA" in tight_check.summary()
    assert "tilt table" in tight_check.likely_cause
    assert any(name.startswith("surface") for name, _ in tight_check.pulled)

    today, today_check = fit(replace(nominal, tolerances=Tolerances()), readings)
    assert not today_check.explained and today.chi2_per_dof > 3 * right.chi2_per_dof


def test_a_turned_camera_is_fitted_however_precise_the_spots() -> None:
    """The camera's yaw about the vertical is set by the emitters' and the table readings'
    declared tolerances: with the spots as precise as averaged stills give them (σ 0.018 px
    in the as-built bench's imaging), it is fitted, not kept from the rig file; kept, the
    fitted emitters and surfaces turned with the camera and every surface's cross-axis tilt
    was off by tenths of a degree."""
    rng = np.random.default_rng(11)
    designed = random_layout(load_rig(STELIUM), rng)
    true = true_rig(designed, RigErrors(emitter_sigma_mm=0.3), rng)
    yaw = Rotation.from_euler("z", 0.8, degrees=True).as_matrix()   # about the world's Z
    camera_to_world = yaw @ true.world_to_camera.rotation.T
    true = replace(true, world_to_camera=RigidTransform(
        camera_to_world.T, -camera_to_world.T @ true.camera_position_mm))
    readings = protocol_readings()
    truths = true_surfaces(readings, SEED_READINGS, rng)
    ids, diode, frame, pixels, covariance = _spots(true, truths, rng, sigma_px=0.018)
    nominal = replace(designed, tolerances=Tolerances(emitter_mm=0.3))
    fit = self_calibrate(nominal, ids, declared(readings, SEED_READINGS), diode, frame,
                         pixels, covariance)
    assert "camera rotation about Z" not in fit.fixed, fit.fixed
    normalised = _normalised_camera_and_surface_errors(fit, true, truths)
    assert np.sqrt(np.mean(normalised**2)) < 1.5 and np.max(np.abs(normalised)) < 4.5


def test_a_rendered_rig_as_built_meets_the_goals_by_the_readmes_protocol() -> None:
    """A random rig as built, rendered in 4K (reflections, the camera file off by one Table 2
    σ), calibrated from its tilt-table images: no wrong identity, the model explained, an
    unseen series about the diagonal within 0.1° and 0.1 mm, honest σ; the same data with the
    table's accuracy declared ten times too tight, or with today's model, are flagged."""
    result = as_built_trial(9001, STELIUM, drop=False)
    assert result["wrong"] == 0
    assert set(result["visible"]) <= set(result["calibrated"]) | set(result["unidentified"])
    assert result["check"].explained, result["check"].summary()
    # the tracker's σ of the spots it found, against the renderer's truth: 0.844 here, 0.842
    # and 0.893 on rigs 9002 and 9003 (0.850, 0.843, 0.894 before a still's σ also read its
    # own weights); the lower bound is the honest band's (0.8), on the safe side
    assert 0.8 < result["spot_sigma_rms"] < 1.15, result["spot_sigma_rms"]
    assert not result["tight_check"].explained
    assert not result["today_check"].explained
    assert result["unseen"].tilt_error_deg <= 0.1
    assert result["unseen"].heights.rmse_mm <= 0.1
    normalised = result["normalised"]
    assert max(normalised.camera, normalised.beams, normalised.surfaces) <= 1.5, normalised
    # all the errors together, against the fit's full covariance
    assert normalised.joint_p > 0.01, normalised
    # today's model on the same data is worse on the unseen series
    assert result["today_unseen"].tilt_error_deg > result["unseen"].tilt_error_deg


def test_the_rig_file_carries_its_tolerances(tmp_path: Path) -> None:
    rig = load_rig(STELIUM)
    assert rig.tolerances == Tolerances() and rig.emitter_sigma_mm(0) == 0.0
    diodes = (replace(rig.diodes[0], emitter_sigma_mm=1.0), *rig.diodes[1:])
    built = replace(rig, diodes=diodes,
                    tolerances=Tolerances(emitter_mm=0.3, camera_angle_deg=2.0))
    loaded = load_rig(save_rig(built, tmp_path / "built.yaml"))
    assert loaded.tolerances == built.tolerances
    assert loaded.emitter_sigma_mm(rig.diodes[0].laser_id) == 1.0
    assert loaded.emitter_sigma_mm(rig.diodes[1].laser_id) == 0.3
    text = (tmp_path / "built.yaml").read_text().replace("emitter_mm: 0.3", "emiter_mm: 0.3")
    (tmp_path / "typo.yaml").write_text(text)
    with pytest.raises(RigError, match=r"typo.yaml: tolerances: unknown keys \['emiter_mm'\]"):
        load_rig(tmp_path / "typo.yaml")


def test_the_surfaces_csv_takes_declared_sigmas(tmp_path: Path) -> None:
    """tilt_sigma_deg is each angle's σ, an angle's own column (0 too) comes before it; the
    fit's priors are what was declared."""
    path = tmp_path / "surfaces.csv"
    path.write_text("frame,tilt_x_deg,tilt_y_deg,offset_mm,tilt_sigma_deg,tilt_y_sigma_deg,"
                    "offset_sigma_mm\n0,0,0,0,0.05,,0.05\n1,10,0,0,0.3,0.15,\n"
                    "2,0,0,-5,0.05,0,0.05\n")
    surfaces = read_surfaces(path)
    assert surfaces[0].tilt_y_sigma_rad == pytest.approx(np.radians(0.05))
    assert surfaces[1].tilt_x_sigma_rad == pytest.approx(np.radians(0.3))
    assert surfaces[1].tilt_y_sigma_rad == pytest.approx(np.radians(0.15))
    assert surfaces[2].tilt_y_sigma_rad == 0.0 and surfaces[2].has_sigma
    assert surfaces[1].offset_sigma_mm == 0.0 and surfaces[2].offset_mm == -5.0
    rig = load_rig(STELIUM)
    table = RigModel(rig, [d.laser_id for d in rig.diodes],
                     [s for _, s in sorted(surfaces.items())]).table
    priors = dict(zip(table.names, table.prior_sigmas, strict=True))
    assert np.degrees(priors["surface 1 tilt y"]) == pytest.approx(0.15)
    assert "surface 2 tilt x" in priors and "surface 2 tilt y" not in priors
    path.write_text("frame,tilt_x_deg,tilt_y_deg,tilt_x_sigma_deg\n0,0,0,-0.1\n")
    with pytest.raises(ValueError, match="line 2: tilt_sigma_deg, tilt_x_sigma_deg"):
        read_surfaces(path)
    path.write_text("frame,tilt_x_deg,tilt_y_deg,tilt_y_sigma_deg\n0,0,0,abc\n")
    with pytest.raises(ValueError, match=r"line 2 needs .* σ column"):
        read_surfaces(path)


def test_the_planner_predicts_the_fits_sigma_and_asks_first_for_a_second_fill_level(
        tmp_path: Path) -> None:
    """The planner's prediction is the joint fit's own σ (same model, same priors); for a rig
    with uncertain emitters its first addition is a second fill level (the camera's height),
    and `sds calibrate plan` writes the plan as a surfaces CSV."""
    rng = np.random.default_rng(31)
    rig = replace(random_layout(load_rig(STELIUM), rng), tolerances=Tolerances(emitter_mm=0.3))
    base, candidates = default_surfaces(rig, Accuracy())
    steps = plan(rig, base, candidates)
    assert steps[1].surfaces[-1].offset_mm != 0.0
    assert steps[-1].worst_tilt_deg < 0.5 * steps[0].worst_tilt_deg
    planned = steps[-1]
    ids, diode, frame, pixels, covariance = _spots(rig, planned.surfaces, rng, sigma_px=0.1)
    fit = self_calibrate(rig, ids, planned.surfaces, diode, frame, pixels, covariance)
    for name in ("camera rotation about X", "camera rotation about Z", "camera Z"):
        predicted = planned.sigmas[planned.names.index(name)]
        assert fit.sigma_of(name) == pytest.approx(predicted, rel=0.25), name
    # and so are the unseen surfaces' tilt σ that the fit's own covariance gives
    own = unseen_tilt_sigmas_deg(unseen_sensitivity(fit.rig), fit.names, fit.covariance)
    np.testing.assert_allclose(own.max(axis=1), planned.tilt_sigma_deg, rtol=0.25)

    # Where the goals are out of reach, what would reach them: each better knowledge lowers
    # the predicted tilt σ, a table read to 0.05° (an inclinometer) the most.
    whatif = dict(what_would_meet_the_goals(rig, Accuracy(), planned))
    assert {what: p.worst_tilt_deg < planned.worst_tilt_deg for what, p in whatif.items()} == \
        dict.fromkeys(whatif, True)
    assert min(whatif, key=lambda what: whatif[what].worst_tilt_deg).startswith(
        "tilted frames read to 0.05 deg")

    # What sets the tilt: a group's share (the posterior conditioned on it) is what a plan
    # with that group known exactly loses, computed by the planner from a new information
    # matrix instead.
    shares = dict(tilt_shares(planned))
    assert all(0.0 <= share <= 1.0 for share in shares.values())
    exact = predict(replace(rig, tolerances=Tolerances(emitter_mm=1e-4)), planned.surfaces)
    gradient = planned.worst_tilt_gradient
    assert shares["emitters' places"] == pytest.approx(
        1.0 - (gradient @ exact.covariance @ gradient)
        / (gradient @ planned.covariance @ gradient), abs=0.02)

    # A table read better across its axis than about it: the plan written, each angle its σ.
    rig_file = save_rig(rig, tmp_path / "rig.yaml")
    done = subprocess.run([SDS, "calibrate", "plan", "--rig", str(rig_file),
                           "--table-across-sigma-deg", "0.15", "--out",
                           str(tmp_path / "plan.csv")], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert "camera Z mm" in done.stdout
    assert "the planned protocol with better knowledge" in done.stdout, done.stdout
    assert "what sets the unseen tilt's sigma" in done.stdout, done.stdout
    written = [s for _, s in sorted(read_surfaces(tmp_path / "plan.csv").items())]
    across = plan_protocol(rig, Accuracy(table_across_deg=0.15))[-1]
    assert [(s.offset_mm, s.tilt_x_rad, s.tilt_y_rad) for s in written] == \
        [(s.offset_mm, s.tilt_x_rad, s.tilt_y_rad) for s in across.surfaces]
    np.testing.assert_allclose(
        [(s.tilt_x_sigma_rad, s.tilt_y_sigma_rad, s.offset_sigma_mm) for s in written],
        [(s.tilt_x_sigma_rad, s.tilt_y_sigma_rad, s.offset_sigma_mm) for s in across.surfaces],
        rtol=1e-5)
    assert np.degrees(written[1].tilt_y_sigma_rad) == pytest.approx(0.15)
    assert across.worst_tilt_deg < planned.worst_tilt_deg


def test_the_readmes_protocol_is_the_plan_for_the_stelium_rig_and_meets_the_height_goal(
        ) -> None:
    """For the StELIUM rig with its emitters to 0.3 mm the planner chooses the README's
    protocol (but for the two tilts about Y that hold the line laser's plane, which it does not
    model): fill levels over the heights a tilted surface reaches, until heights meet their
    goal even where the tilts' goal is out of reach (the table's readings set their floor)."""
    rig = replace(load_rig(STELIUM), tolerances=Tolerances(emitter_mm=0.3))
    steps = plan_protocol(rig, Accuracy())
    planned = steps[-1]

    def described(surfaces: list[KnownSurface]) -> set[tuple[float, float, float]]:
        return {(round(float(np.degrees(s.tilt_x_rad)), 3),
                 round(float(np.degrees(s.tilt_y_rad)), 3), s.offset_mm) for s in surfaces}

    line_plane_only = {(0.0, 12.5, 0.0), (0.0, 22.5, 0.0)}
    assert described(planned.surfaces) == described(protocol_readings()) - line_plane_only
    assert planned.worst_height_mm <= HEIGHT_GOAL_MM < steps[0].worst_height_mm
    # a step taken for the heights alone: the tilt σ moved by less than the least gain
    assert any(after.worst_tilt_deg > 0.9 * before.worst_tilt_deg
               and after.worst_height_mm <= 0.9 * before.worst_height_mm
               for before, after in itertools.pairwise(steps))
    assert "goal tilt 0.033 deg not met (height 0.033 mm met)" in plan_text(steps)


def test_a_wrong_model_keeps_every_diode_and_is_flagged_not_emptied() -> None:
    """Emitters declared but the table's readings taken as exact: every emitter is pulled
    alike (5-10 σ), which is the model's fault, not a swap: no diode is dropped for it, and
    the model check says the model does not explain the data."""
    rng = np.random.default_rng(13)
    designed = random_layout(load_rig(STELIUM), rng)
    true = true_rig(designed, RigErrors(emitter_sigma_mm=0.3), rng)
    readings = protocol_readings()
    truths = true_surfaces(readings, SEED_READINGS, rng)
    ids, _, frame, pixels, covariance = _spots(true, truths, rng)
    blobs = [pixels[frame == f] for f in range(len(readings))]
    covariances = [covariance[frame == f] for f in range(len(readings))]
    result = calibrate_rig(replace(designed, tolerances=Tolerances(emitter_mm=0.3)), readings,
                           blobs, covariances)
    assert sorted(result.laser_ids) == sorted(ids) and not result.unidentified
    assert not result.check.explained
