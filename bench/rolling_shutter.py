"""Points, fits and modes under a rolling shutter, on random rigs, at 1 g and in microgravity.

Usage: python bench/rolling_shutter.py [--rigs 3] [--first-seed 8100] [--seconds 1.5]
                                       [--as-built] [--out /tmp/bench_rolling]

For each random diode layout (`sds_sim.true_rig.random_layout` of the StELIUM rig) and each
scenario (`ground_kick`: 1 g; `drop_4p7s`: microgravity), the scenario is rendered in 4K with
a global shutter and with rows read top to bottom over 20 ms and 30 ms, the camera file
stating the true readout, and processed by `process_video`. Printed per run, over the frames
after the kick: every spot point's height against the true surface at its `t_sample_s` and
at its frame's time (what the results claimed before per-point times); each frame's modal fit
against the true surface at the frame's time at the diodes' places, and the same fit of the
points as measured (before the fits were carried to the frame's time).

With `--as-built`, each rig is a random rig as built (`calibration_trial.first_use`: leaning
beams, camera pose, emitters, camera file off by its σ, table readings off by their accuracy),
calibrated by docs/rig.md's protocol from its tilt images; the drops are rendered with the true
rig and processed with the calibrated one, its camera file stating the readout 0.5 ms long
(the tolerance `sds camera readout` is held to). Each scenario runs whole (ground_kick 6 s,
drop_4p7s 4.7 s, or `--seconds`), and each mode's frequency and damping ratio (matrix pencil)
is printed against the simulator's truth and against the global shutter's, in their σ.
"""

from __future__ import annotations

import argparse
import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
from sds_model.camera.rolling_shutter import RollingShutter
from sds_model.rig import Rig, load_rig, save_rig
from sds_recon.reconstruction import SurfacePoints, fit_surface
from sds_recon.results import Results, load_results
from sds_recon.surface_fit import ModalFit, modal_heights
from sds_sim.rolling_shutter import rolling_rig, rolling_scenario
from sds_sim.scenario import Scenario, load_scenario
from sds_sim.simulate import SimulationOutput, simulate
from sds_sim.true_rig import random_layout
from sds_sloshing.report import truth_from_run
from sds_workflows.calibration_trial import first_use
from sds_workflows.process import ProcessedRun

from sds_workflows import process_video

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = ("ground_kick", "drop_4p7s")
READOUTS_S = (0.0, 0.020, 0.030)
STATED_OFF_S = 0.0005
"""How far the camera file's readout is off in the as-built runs [s]."""
METHOD = "matrix_pencil"
SETTLE_S = 0.1
"""Frames this long after the kick on are compared (before it the surface is flat)."""


def rms(values: list[float] | np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def heights(scenario: Scenario, times_s, x_mm, y_mm) -> np.ndarray:
    """The simulator's true surface at each point and time."""
    return np.array([scenario.surface_at(t).height(x, y, t)
                     for t, x, y in zip(times_s, x_mm, y_mm, strict=True)])


def point_errors(scenario: Scenario, results: Results) -> tuple[float, float]:
    """Spot points' height RMSE against the surface at their sample time and at the frame's."""
    assert results.points is not None
    points = results.points
    points = points[(points["laser_id"] != 65535) & (points["rejected"] == 0)
                    & (points["t_s"] > scenario.kick_s + SETTLE_S)]
    sample_s = points["t_sample_s"] if "t_sample_s" in points.dtype.names else points["t_s"]
    x, y, z = points["X_mm"], points["Y_mm"], points["Z_mm"]
    return (rms(z - heights(scenario, sample_s, x, y)),
            rms(z - heights(scenario, points["t_s"], x, y)))


def fit_errors(scenario: Scenario, simulation: SimulationOutput, results: Results
               ) -> tuple[float, float]:
    """Modal fits' RMSE at the diodes' places against the surface at the frame's time: the
    results' fits, and a fit of the frame's points as measured."""
    assert results.fits is not None and results.points is not None
    radius = scenario.rig.container.radius_mm
    names = tuple(n.removesuffix("_mm") for n in results.fits.dtype.names
                  if n.endswith("_mm") and n not in ("p00_mm", "rmse_mm"))
    places: dict[int, list[tuple[float, float]]] = {}
    with simulation.spots.open() as file:
        for row in csv.DictReader(file):
            places.setdefault(int(row["frame"]), []).append((float(row["X_mm"]),
                                                             float(row["Y_mm"])))
    points = results.points[results.points["laser_id"] != 65535]
    fitted, measured = [], []
    for fit in results.fits[results.fits["t_s"] > scenario.kick_s + SETTLE_S]:
        frame, time_s = int(fit["frame"]), float(fit["t_s"])
        xy = np.array([p for p in places[frame] if np.isfinite(p).all()])
        true = scenario.surface_at(time_s).height(xy[:, 0], xy[:, 1], time_s)
        amplitudes = np.array([fit[f"{n}_mm"] for n in names])
        if not np.isfinite(amplitudes).all():
            continue
        fitted += list(modal_heights(ModalFit(names, amplitudes, 0.0, 0), xy, radius) - true)
        rows = points[points["frame"] == frame]
        refit = fit_surface(SurfacePoints(
            rows["laser_id"], np.column_stack([rows["X_mm"], rows["Y_mm"], rows["Z_mm"]]),
            rows["sigma_Z_mm"], rows["miss_mm"]), radius).modal
        if refit is not None:
            measured += list(modal_heights(refit, xy, radius) - true)
    return rms(fitted), rms(measured)


def one_run(folder: Path, name: str, rig_seed: int, readout_s: float, seconds: float
            ) -> tuple[float, float, float, float]:
    """Render and process one scenario on one random rig with one readout; its four RMSEs."""
    drawn = rolling_rig(REPO / "config" / "rigs" / "stelium.yaml", readout_s, folder / "drawn")
    rig = random_layout(load_rig(drawn), np.random.default_rng(rig_seed))
    rig_file = save_rig(rig, folder / "rig.yaml")
    scenario = load_scenario(rolling_scenario(REPO / "config" / "scenarios" / f"{name}.yaml",
                                              rig_file, readout_s, folder),
                             {"duration_s": seconds})
    simulation = simulate(scenario, folder / "sim", progress=False)
    process_video(simulation.video, load_rig(rig_file), folder / "results", progress=False)
    results = load_results(folder / "results")
    return (*point_errors(scenario, results), *fit_errors(scenario, simulation, results))


Modes = dict[str, tuple[float, float, float, float]]
"""Mode name → (frequency [Hz], its σ, damping ratio, its σ)."""


def modes(run: ProcessedRun) -> Modes:
    """Each mode's METHOD estimate in a processed run."""
    found: Modes = {}
    for mode in (run.analysis.results or {}).get("modes", []):
        for estimate in mode["estimates"]:
            if estimate["method"] == METHOD:
                found[mode["mode"]] = (estimate["frequency_hz"], estimate["frequency_sigma_hz"],
                                       estimate["damping_ratio"], estimate["damping_ratio_sigma"])
    return found


def as_built_run(folder: Path, name: str, true: Rig, calibrated: Rig, readout_s: float,
                 seconds: float | None) -> tuple[tuple[float, float, float, float], Modes,
                                                 dict[str, tuple[float, float]]]:
    """Render a scenario with the true rig and `readout_s`, process it with the calibrated rig
    told a readout STATED_OFF_S longer: the four RMSEs, the modes and the truth's modes."""
    file = REPO / "config" / "scenarios" / f"{name}.yaml"
    scenario = load_scenario(file, {"duration_s": seconds} if seconds else None)
    scenario = replace(scenario, rig=true, sensor=replace(scenario.sensor, readout_s=readout_s))
    simulation = simulate(scenario, folder / "sim", progress=False)
    stated = RollingShutter(readout_s + STATED_OFF_S if readout_s else 0.0)
    run = process_video(simulation.video, replace(calibrated, camera_shutter=stated),
                        folder / "results", progress=False, overwrite=True)
    results = load_results(folder / "results")
    return ((*point_errors(scenario, results), *fit_errors(scenario, simulation, results)),
            modes(run), truth_from_run(simulation.run))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rigs", type=int, default=3)
    parser.add_argument("--first-seed", type=int, default=8100)
    parser.add_argument("--seconds", type=float, default=None,
                        help="scenario length [s] (default 1.5; with --as-built the whole "
                             "scenario)")
    parser.add_argument("--as-built", action="store_true",
                        help="random rigs as built, calibrated; modes against the truth")
    parser.add_argument("--out", type=Path, default=Path("/tmp/bench_rolling"))
    args = parser.parse_args()
    print("scenario     rig seed readout  points@t_sample points@frame  fit@frame  fit(measured)"
          "   [mm RMSE]")
    if args.as_built:
        as_built(args)
        return
    for name in SCENARIOS:
        for seed in range(args.first_seed, args.first_seed + args.rigs):
            for readout_s in READOUTS_S:
                folder = args.out / f"{name}_{seed}_{round(readout_s * 1e3)}ms"
                errors = one_run(folder, name, seed, readout_s, args.seconds or 1.5)
                print(f"{name:<12} {seed:>8} {readout_s * 1e3:5.0f} ms " + "  ".join(
                    f"{e:13.3f}" for e in errors), flush=True)


def as_built(args: argparse.Namespace) -> None:
    """The --as-built runs: per rig and scenario, the RMSEs of each readout, then each mode's
    error against the truth and the change from the global shutter, in σ."""
    for seed in range(args.first_seed, args.first_seed + args.rigs):
        first = first_use(seed, REPO / "config" / "rigs" / "stelium.yaml")
        calibrated = first.calibrated
        print(f"rig {seed}: {len(first.result.laser_ids)} diodes calibrated, chi2/dof "
              f"{first.result.check.chi2_per_dof:.2f}", flush=True)
        for name in SCENARIOS:
            found: dict[float, Modes] = {}
            for readout_s in READOUTS_S:
                folder = args.out / f"as_built_{name}_{seed}_{round(readout_s * 1e3)}ms"
                errors, found[readout_s], truth = as_built_run(
                    folder, name, first.true, calibrated, readout_s, args.seconds)
                print(f"{name:<12} {seed:>8} {readout_s * 1e3:5.0f} ms " + "  ".join(
                    f"{e:13.3f}" for e in errors), flush=True)
            for mode, (f_true, zeta_true) in truth.items():
                cells = []
                for readout_s, estimates in found.items():
                    if mode not in estimates:
                        cells.append(f"{readout_s * 1e3:.0f} ms: not found")
                        continue
                    f, f_sigma, zeta, zeta_sigma = estimates[mode]
                    cell = (f"{readout_s * 1e3:.0f} ms: f {f:.4f}±{f_sigma:.4f} Hz "
                            f"({(f - f_true) / f_sigma:+.2f}σ) zeta {zeta:.4f}±{zeta_sigma:.4f} "
                            f"({(zeta - zeta_true) / zeta_sigma:+.2f}σ)")
                    if readout_s and mode in found[0.0]:
                        f0, _, zeta0, _ = found[0.0][mode]
                        cell += (f", from global {(f - f0) / f_sigma:+.2f}σ, "
                                 f"{(zeta - zeta0) / zeta_sigma:+.2f}σ")
                    cells.append(cell)
                print(f"  {name} {mode} (truth {f_true:.4f} Hz, zeta {zeta_true:.4f}): "
                      + "; ".join(cells), flush=True)


if __name__ == "__main__":
    main()
