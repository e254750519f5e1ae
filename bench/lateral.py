"""The side camera on random rigs as built, at 1 g and in microgravity (issue 36).

Usage: python bench/lateral.py [--rigs 3] [--first-seed 8300] [--seconds S]
                               [--out /tmp/bench_lateral]
       python bench/lateral.py --pose-draws 12 [--first-seed 8400]

For each seed, a random rig as built (`calibration_trial.first_use`: leaning beams, camera
pose, emitters, camera file off by its σ, the table's readings off by their accuracy) is
calibrated by docs/rig.md's protocol from its tilt images. A random side camera stands beside
it: its centre off the view file's drawing by up to ±5 mm across, ±10 mm in distance, ±3 mm
in height, looking up to ±3 mm off, turned up to ±1° about its axis; its intrinsics off their
file by one σ each; the checkerboard off its stated places by its placement σ per axis; its
clock started at a random time before the LED's blink and running 15 ppm fast; the blink at
a random phase of the top camera's frames. The 1 g kick
(6 s) and the microgravity drop (4.7 s) are rendered whole, the top view in 4K (30 fps) and
the side view at 125 fps (both H.264), and processed by `process_video` with the calibrated
rig, the side camera's video, view file and board image, the top video's LED region and the
Arduino's SD log. Printed per rig and scenario:
- the clock link's error against the truth, each path's error, and the combined σ;
- the side profile's height RMSE against the true surface at the wall (at each point's
  azimuth and the side frame's true time), and the largest frame's RMSE;
- the top/side comparison: side − top on average, its scatter about that mean, and what the
  side's image noise, the top fit's σ and the clock's σ predict for it;
- the wave's own clock against the truth, the tilt between the two surfaces at the wall, and
  the scatter left once the offset, the tilt and the time shift are taken out, against what
  the side's noise and the top fit's σ predict.

With `--pose-draws N`, only the side camera's pose is checked, on N random side cameras (as
above) looking at the flat liquid: the wall heights' mean error against the pose's σ, with
the view file's two board placements and with the mid-plane board alone.
"""

from __future__ import annotations

import argparse
import csv
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
from sds_sim.scenario import LateralSpec, Scenario, load_scenario
from sds_sim.simulate import simulate
from sds_workflows.calibration_trial import FirstUse, first_use

from sds_workflows import LateralInput, process_video

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = ("ground_kick", "drop_4p7s")
VIEW_FILE = REPO / "config" / "lateral" / "stelium_side.yaml"
TOP_LED_ROI = (200, 200, 40, 40)
"""The top camera's LED region around the simulator's LED at (220, 220) px in 4K."""


def side_camera(rng: np.random.Generator, led_on_s: float) -> LateralSpec:
    """A random side camera as built (see the module's docstring)."""
    drawn = LateralSpec()
    position = np.array(drawn.position_mm) + rng.uniform(-1, 1, 3) * (5.0, 10.0, 3.0)
    look_at = np.array(drawn.look_at_mm) + rng.uniform(-3.0, 3.0, 3)
    return replace(drawn, view_file=str(VIEW_FILE), position_mm=tuple(position),
                   look_at_mm=tuple(look_at), roll_deg=float(rng.uniform(-1.0, 1.0)),
                   clock_offset_s=float(rng.uniform(-0.3, led_on_s - 0.1)),
                   intrinsics_off_sigmas=1.0,
                   board_offset_mm=tuple(rng.normal(0.0, 0.1, 3)))


def rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def profile_errors(scenario: Scenario, folder: Path) -> tuple[float, float, float, int]:
    """The side profile's height RMSE [mm] against the true surface at the wall, its mean
    error [mm], the largest frame's RMSE, and the points compared."""
    truth = {int(row["frame"]): float(row["time_s"])
             for row in csv.DictReader((folder / "sim" / "truth" / "lateral.csv").open())}
    radius = scenario.rig.container.radius_mm
    by_frame: dict[int, list[float]] = {}
    for row in csv.DictReader((folder / "results" / "lateral_profile.csv").open()):
        frame = int(row["frame"])
        time_s = truth[frame]
        azimuth = np.radians(float(row["azimuth_deg"]))
        true_mm = float(scenario.surface_at(time_s).height(
            radius * np.cos(azimuth), radius * np.sin(azimuth), time_s))
        by_frame.setdefault(frame, []).append(float(row["Z_mm"]) - true_mm)
    errors = np.concatenate([np.array(v) for v in by_frame.values()])
    return (rms(errors), float(np.mean(errors)),
            max(rms(np.array(v)) for v in by_frame.values()), errors.size)


def one_run(folder: Path, name: str, seed: int, first: FirstUse, rng: np.random.Generator,
            seconds: float | None) -> None:
    """Render one scenario on one rig with a random side camera, process it, print a line."""
    file = REPO / "config" / "scenarios" / f"{name}.yaml"
    scenario = load_scenario(file, {"duration_s": seconds} if seconds else None)
    # The LED switches at any phase of the top camera's frames (the scenario's on a frame).
    shift = rng.uniform(0.0, 1.0 / scenario.fps)
    events = replace(scenario.events, led_on_s=scenario.events.led_on_s + shift,
                     led_off_s=scenario.events.led_off_s + shift)
    spec = side_camera(rng, events.led_on_s)
    scenario = replace(scenario, rig=first.true, lateral=spec, events=events)
    simulation = simulate(scenario, folder / "sim", progress=False)
    assert simulation.lateral_video is not None and simulation.lateral_boards
    run = process_video(simulation.video, first.calibrated, folder / "results", progress=False,
                        overwrite=True,
                        lateral=LateralInput(simulation.lateral_video, VIEW_FILE,
                                             simulation.lateral_boards, TOP_LED_ROI,
                                             simulation.sd_log))
    assert run.lateral is not None
    clock, summary = run.lateral.clock, run.lateral.summary
    true_offset = spec.clock_offset_s
    paths = "; ".join(f"{p.name}: {(p.offset_s - true_offset) * 1e3:+.2f} ± "
                      f"{p.sigma_s * 1e3:.2f} ms" for p in clock.paths)
    profile_rmse, profile_mean, worst_frame, points = profile_errors(scenario, folder)
    print(f"{name:<12} rig {seed}  clock {(clock.offset_s - true_offset) * 1e3:+6.2f} ± "
          f"{clock.sigma_s * 1e3:.2f} ms ({paths})", flush=True)
    print(f"{'':<12} profile RMSE {profile_rmse:.3f} mm (mean {profile_mean:+.3f}, worst "
          f"frame {worst_frame:.3f}, {points} points); side − top "
          f"{summary.mean_difference_mm:+.3f} mm "
          f"(pose σ {summary.pose_sigma_mm:.3f}), scatter {summary.scatter_mm:.3f} mm, "
          f"predicted {summary.predicted_mm:.3f} mm (ratio "
          f"{summary.scatter_mm / summary.predicted_mm:.2f}), {summary.frames} frames",
          flush=True)
    wave_error_s = clock.offset_s + summary.wave_shift_s - true_offset
    print(f"{'':<12} the wave's clock {wave_error_s * 1e3:+.2f} ± "
          f"{summary.wave_shift_sigma_s * 1e3:.2f} ms off the truth "
          f"({wave_error_s / summary.wave_shift_sigma_s:+.1f} σ); tilt γx, γy "
          f"{summary.tilt_deg[0]:+.3f} ± {summary.tilt_sigma_deg[0]:.3f}°, "
          f"{summary.tilt_deg[1]:+.3f} ± {summary.tilt_sigma_deg[1]:.3f}°; aligned scatter "
          f"{summary.aligned_scatter_mm:.3f} mm, predicted {summary.aligned_predicted_mm:.3f} "
          f"mm (ratio {summary.aligned_scatter_mm / summary.aligned_predicted_mm:.2f})",
          flush=True)
    record = {"scenario": name, "seed": seed, "clock_error_s": clock.offset_s - true_offset,
              "clock_sigma_s": clock.sigma_s, "profile_rmse_mm": profile_rmse,
              "profile_mean_mm": profile_mean, "pose_sigma_mm": summary.pose_sigma_mm,
              "worst_frame_rmse_mm": worst_frame, "mean_difference_mm":
              summary.mean_difference_mm, "scatter_mm": summary.scatter_mm,
              "predicted_mm": summary.predicted_mm, "wave_error_s": wave_error_s,
              "wave_sigma_s": summary.wave_shift_sigma_s, "tilt_deg": summary.tilt_deg,
              "tilt_sigma_deg": summary.tilt_sigma_deg,
              "aligned_scatter_mm": summary.aligned_scatter_mm,
              "aligned_predicted_mm": summary.aligned_predicted_mm}
    (folder / "bench.json").write_text(json.dumps(record, indent=2) + "\n")


def pose_check(draws: int, first_seed: int) -> None:
    """The side camera's pose alone: the flat liquid's wall heights on random side cameras,
    placed by both boards and by the mid-plane board alone; their mean error against σ."""
    from sds_lateral.board import camera_pose_from_boards
    from sds_lateral.wall_profile import WallProfiler
    from sds_sim.lateral import LateralRenderer

    errors: dict[str, list[tuple[float, float]]] = {"both boards": [], "mid-plane board": []}
    for seed in range(first_seed, first_seed + draws):
        rng = np.random.default_rng(seed)
        scenario = load_scenario(REPO / "config" / "scenarios" / "ground_kick.yaml",
                                 {"duration_s": 0.2})
        renderer = LateralRenderer(replace(scenario, lateral=side_camera(rng, 0.3), seed=seed))
        view, images = renderer.view, renderer.board_images()
        frame, truth = renderer.render(0)
        for label, chosen in (("both boards", slice(None)), ("mid-plane board", slice(1, 2))):
            pose = camera_pose_from_boards(images[chosen], view.boards[chosen], view.camera,
                                           view.camera_sigma)
            profile = WallProfiler(view.camera, pose.world_to_camera, renderer.radius_mm,
                                   pose).profile(frame)
            valid = profile.valid
            azimuth = profile.azimuth_rad[valid]
            true_mm = scenario.surface_at(truth.time_s).height(
                renderer.radius_mm * np.cos(azimuth), renderer.radius_mm * np.sin(azimuth),
                truth.time_s)
            error = float(np.mean(profile.wall_mm[valid, 2] - true_mm))
            errors[label].append((error, rms(profile.pose_sigma_z_mm[valid])))
    for label, values in errors.items():
        error, sigma = np.array(values).T
        print(f"{label}: wall height's mean error RMS {rms(error):.3f} mm, max "
              f"{np.max(np.abs(error)):.3f} mm; pose σ RMS {rms(sigma):.3f} mm; error/σ RMS "
              f"{rms(error / sigma):.2f} ({draws} side cameras, seeds {first_seed}-"
              f"{first_seed + draws - 1})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rigs", type=int, default=3)
    parser.add_argument("--first-seed", type=int, default=8300)
    parser.add_argument("--seconds", type=float, default=None,
                        help="scenario length [s] (default: the whole scenario)")
    parser.add_argument("--out", type=Path, default=Path("/tmp/bench_lateral"))
    parser.add_argument("--pose-draws", type=int, default=0,
                        help="check only the side camera's pose, on this many random cameras")
    args = parser.parse_args()
    if args.pose_draws:
        pose_check(args.pose_draws, args.first_seed)
        return
    for seed in range(args.first_seed, args.first_seed + args.rigs):
        first = first_use(seed, REPO / "config" / "rigs" / "stelium.yaml")
        print(f"rig {seed}: {len(first.result.laser_ids)} diodes calibrated, chi2/dof "
              f"{first.result.check.chi2_per_dof:.2f}", flush=True)
        rng = np.random.default_rng(seed + 36)
        for name in SCENARIOS:
            one_run(args.out / f"{name}_{seed}", name, seed, first, rng, args.seconds)


if __name__ == "__main__":
    main()
