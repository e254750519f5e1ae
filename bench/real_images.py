"""Tracking on a real camera's images: the tracker against a naive windowed centroid.

Usage: python bench/real_images.py [--seeds 7001 7002 7003 7004] [--frames 30] [--scale 0.5]
For each seed a random rig as built (`calibration_trial.rig_as_built`) is rendered sloshing in
1 g (config/scenarios/ground_kick.yaml) with one real-camera effect at a time
(`sds_sim.imaging.EFFECTS`, each drawn from its range for that seed), the camera's H.264 at its
bit rate, and all of them at once; the tracker follows the spots with the true rig (tracking
alone: no calibration error) and the σ scale the calibration's repeated frames would give it
(`sds_tracker.sigma_scale`, from REST_FRAMES frames of the rig at rest with the same imaging
and noise of their own). Per effect it prints, over every visible spot of every seed:
the tracker's RMS error against the truth and a naive windowed centroid's on the same spots
(median of the window's border as background, a round aperture, re-centred twice, started at
the true spot: it cannot take another diode's blob), their ratio, both errors' medians (the
naive centroid's RMS is dominated by the spots the laser line passes), error/σ RMS of the
tracker's own σ, the run's own check of it without the truth (path/σ: the spots' scatter
across their beams' image paths over their σ, `sds_tracker.path_scatter`), wrong identities
(a valid spot more than 2 px from its own diode's truth), spots given while their diode was
hidden (fabricated), and visible spots not measured.
"""

from __future__ import annotations

import argparse
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np
from sds_camera.frame_source import Region, VideoFileSource
from sds_camera.video_writer import VideoWriter
from sds_model.rig import Rig, load_rig
from sds_sim.imaging import EFFECTS, draw_imaging, merged
from sds_sim.render import FrameRenderer, FrameTruth
from sds_sim.scenario import Scenario, load_scenario
from sds_tracker.path_scatter import PathScatter
from sds_tracker.sigma_scale import video_sigma_scale
from sds_tracker.spots import is_measured
from sds_tracker.tracker import FrameTracker, TrackedSpot
from sds_workflows.calibration_trial import AsBuilt, rig_as_built

REPO = Path(__file__).resolve().parents[1]
SCENARIO = REPO / "config" / "scenarios" / "ground_kick.yaml"
CASES = ("clean", *EFFECTS, "codec", "all")
REST_FRAMES = 15
"""Frames of the rig at rest whose spots' scatter gives the σ scale (the calibration's
repeated frames: three stills of five)."""
REST_SEED_OFFSET = 1000
"""The rest clip's noise seed is the video's plus this: its speckle and noise are its own."""


def scenario_for(seed: int, case: str, frames: int, scale: float, true: Rig) -> Scenario:
    """The ground kick of the true rig with the case's imaging, drawn for this seed."""
    effects = EFFECTS if case == "all" else (case,) if case in EFFECTS else ()
    base = {"duration_s": frames / 30, "scale": scale, "seed": seed}
    scenario = load_scenario(SCENARIO, merged(base, draw_imaging(np.random.default_rng(seed),
                                                                 effects)))
    return replace(scenario, rig=true)


def frames_of(scenario: Scenario, encoded: bool, folder: Path
              ) -> tuple[list[np.ndarray], list[FrameTruth]]:
    """The rendered frames (red channel), through the camera's H.264 if `encoded`."""
    renderer = FrameRenderer(scenario)
    rendered = [renderer.render(index) for index in range(scenario.frame_count)]
    truths = [truth for _, truth in rendered]
    if not encoded:
        return [image[..., 2] for image, _ in rendered], truths
    path = folder / "video.mp4"
    height, width = rendered[0][0].shape[:2]
    rate = scenario.sensor.bitrate_mbit_s * 1e6 * scenario.scale**2
    with VideoWriter(path, width, height, scenario.fps, bitrate_bit_s=rate) as writer:
        for image, _ in rendered:
            writer.write(image)
    region = Region(0, 0, width, height)
    return [frame.image for frame in VideoFileSource(path).frames(region, "red")], truths


def with_sigma_scale(true: Rig, scenario: Scenario, encoded: bool, folder: Path) -> Rig:
    """The true rig with the σ scale `video_sigma_scale` gives on REST_FRAMES frames of it at
    rest (the scenario before its kick, with noise of its own), as the calibration's record
    holds it."""
    rest = replace(scenario, seed=scenario.seed + REST_SEED_OFFSET,
                   duration_s=REST_FRAMES / scenario.fps, kick_s=REST_FRAMES / scenario.fps)
    frames, _ = frames_of(rest, encoded, folder)
    factor = video_sigma_scale(replace(true, camera=true.camera.scaled(scenario.scale)),
                               [frames], (0, 0))
    if factor is None:
        return true
    return replace(true, calibration={**(true.calibration or {}), "spot_sigma_scale": factor})


def naive_centroid(red: np.ndarray, start: np.ndarray, half: int) -> np.ndarray:
    """Centroid [px] of the background-subtracted light (median of the window's border) in
    an aperture of radius half/2 around `start`, re-centred twice; NaN off the image."""
    centre = start.astype(float)
    for _ in range(3):
        x, y = np.round(centre).astype(int)
        if x - half < 0 or y - half < 0 or x + half >= red.shape[1] or y + half >= red.shape[0]:
            return np.full(2, np.nan)
        window = red[y - half:y + half + 1, x - half:x + half + 1].astype(float)
        border = np.concatenate([window[0], window[-1], window[:, 0], window[:, -1]])
        rows, columns = np.mgrid[-half:half + 1, -half:half + 1]
        inside = (columns + x - centre[0]) ** 2 + (rows + y - centre[1]) ** 2 <= (half / 2) ** 2
        weights = np.clip(window - np.median(border), 0, None) * inside
        if weights.sum() <= 0:
            return np.full(2, np.nan)
        centre = np.array([np.sum(weights * (columns + x)), np.sum(weights * (rows + y))]) / \
            weights.sum()
    return centre


def measure(true: Rig, scale: float, frames: list[np.ndarray], truths: list[FrameTruth]
            ) -> dict[str, list]:
    """Track the frames with the true rig; per visible spot the tracker's and the naive
    centroid's errors, the tracker's σ; wrong, fabricated and missed spots."""
    rig = replace(true, camera=true.camera.scaled(scale))
    tracker = FrameTracker(rig)
    outputs: list[tuple[int, list[TrackedSpot]]] = []
    for index, red in enumerate(frames):
        outputs += tracker.process(index, red, (0, 0))[0]
    outputs += tracker.flush()
    ids = [d.laser_id for d in rig.diodes]
    half = max(6, round(24 * scale))
    result: dict[str, list] = {"tracker": [], "naive": [], "sigma": [], "wrong": [],
                               "fabricated": [], "missed": [], "path_check": []}
    scatter = PathScatter.for_rig(rig)
    for index, spots in outputs:
        truth = truths[index]
        measured = [s for s in spots if is_measured(s.flags)]
        scatter.add(np.array([s.laser_id for s in measured]),
                    np.array([[s.x_raw_px, s.y_raw_px] for s in measured]).reshape(-1, 2),
                    np.array([s.sigma_px for s in measured]))
        for spot in spots:
            k = ids.index(spot.laser_id)
            measured = is_measured(spot.flags)
            if not truth.visible[k]:
                result["fabricated"].append(measured)
                continue
            if not measured:
                result["missed"].append(1)
                continue
            error = np.array([spot.x_raw_px, spot.y_raw_px]) - truth.spot_exposure_px[k]
            if np.hypot(*error) > 2.0:
                result["wrong"].append(1)
                continue
            naive = naive_centroid(frames[index], np.round(truth.spot_exposure_px[k]), half)
            if not np.isfinite(naive).all():
                continue
            result["tracker"].append(error)
            result["naive"].append(naive - truth.spot_exposure_px[k])
            result["sigma"].append(spot.sigma_px)
    check = scatter.check()
    if check is not None:   # its χ² and degrees of freedom, to pool over the seeds
        dof = check.measurements - check.spots
        result["path_check"].append((check.scatter_over_sigma**2 * dof, dof))
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[7001, 7002, 7003, 7004])
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--scale", type=float, default=0.5)
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES)
    args = parser.parse_args()
    base = load_rig(REPO / "config" / "rigs" / "stelium.yaml")
    print(f"seeds {args.seeds}, {args.frames} frames each at scale {args.scale}, "
          "tracked with the true rig")
    print(f"{'case':20s} {'spots':>6s} {'tracker px':>10s} {'naive px':>9s} {'ratio':>6s} "
          f"{'median':>13s} {'err/σ':>6s} {'path/σ':>6s} {'wrong':>6s} {'fabric.':>7s} "
          f"{'missed':>6s}")
    with tempfile.TemporaryDirectory(prefix="sds-bench-real-") as folder:
        for case in args.cases:
            total: dict[str, list] = {}
            for seed in args.seeds:
                _, true = rig_as_built(base, AsBuilt(), np.random.default_rng(seed))
                scenario = scenario_for(seed, case, args.frames, args.scale, true)
                encoded = case in ("codec", "all")
                frames, truths = frames_of(scenario, encoded, Path(folder))
                rig = with_sigma_scale(true, scenario, encoded, Path(folder))
                for key, values in measure(rig, args.scale, frames, truths).items():
                    total.setdefault(key, []).extend(values)
            tracker, naive = np.array(total["tracker"]), np.array(total["naive"])
            rms_tracker = float(np.sqrt(np.mean(np.sum(tracker**2, axis=1))))
            rms_naive = float(np.sqrt(np.mean(np.sum(naive**2, axis=1))))
            in_sigma = float(np.sqrt(np.mean(np.sum(tracker**2, axis=1) /
                                             (2 * np.array(total["sigma"]) ** 2))))
            medians = [float(np.median(np.hypot(*e.T))) for e in (tracker, naive)]
            chi2, dof = np.sum(np.array(total["path_check"]).reshape(-1, 2), axis=0)
            path_check = float(np.sqrt(chi2 / dof)) if dof else float("nan")
            print(f"{case:20s} {len(tracker):6d} {rms_tracker:10.3f} {rms_naive:9.3f} "
                  f"{rms_tracker / rms_naive:6.2f} {medians[0]:6.3f} {medians[1]:6.3f} "
                  f"{in_sigma:6.2f} {path_check:6.2f} {len(total['wrong']):6d} "
                  f"{sum(total['fabricated']):7d} {len(total['missed']):6d}", flush=True)


if __name__ == "__main__":
    main()
