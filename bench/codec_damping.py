"""Damping ratios against the video's bit rate: what H.264 does to sub-pixel spot motion.

Usage: python bench/codec_damping.py [--scenario config/scenarios/ground_kick.yaml]
                                     [--rates lossless 60 crf18] [--seed 1] [--out DIR]

The scenario is rendered once in 4K without loss, then encoded again at each rate: `lossless`,
a number (Mbit/s at 4K, as a camera records: GoPro states 60 for its HERO5 cameras), or `crf18`
(the constant quality the simulator wrote before, about 4 Mbit/s at 4K for these dark
frames). Each video is processed by `sds process` with the scenario's rig. Printed per rate:
the file's bit rate; each spot's motion along its path regressed on its true motion, early
(the first 1.5 s after the kick) and late (the last 2 s), for the spots that move least in
the image; and each mode's frequency and damping ratio (matrix pencil) against the truth, in
its own σ.
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from sds_camera.frame_source import VideoFileSource
from sds_camera.video_writer import VideoWriter
from sds_model.rig import load_rig
from sds_sim.scenario import load_scenario
from sds_sim.simulate import simulate
from sds_sloshing.report import truth_from_run
from sds_workflows.pipeline import FramePipeline, video_frames

REPO = Path(__file__).resolve().parents[1]
EARLY_S = 1.5
LATE_S = 2.0


def encode(lossless: Path, rate: str, target: Path, fps: float) -> None:
    """`lossless` encoded again at `rate` ('crf18' or Mbit/s at 4K)."""
    source = VideoFileSource(lossless)
    writer: VideoWriter | None = None
    for frame in source.frames(channel="bgr"):
        if writer is None:
            height, width = frame.image.shape[:2]
            scale2 = width * height / (3840 * 2160)
            writer = VideoWriter(target, width, height, fps, bitrate_bit_s=None
                                 if rate == "crf18" else float(rate) * 1e6 * scale2)
        writer.write(frame.image)
    source.close()
    assert writer is not None
    writer.close()


def spot_gains(video: Path, scenario_rig: Path, truth_spots: Path, kick_s: float, end_s: float
               ) -> list[tuple[int, float, float, float]]:
    """Per spot: RMS true motion [px] late, and the gain of its raw motion on the true one,
    early and late."""
    rig = load_rig(scenario_rig)
    tracked: dict[tuple[int, int], tuple[float, float]] = {}
    for step in FramePipeline(rig).run(video_frames(video, rig)):
        for frame in step.spot_frames:
            tracked.update({(frame.index, s.laser_id): (s.x_raw_px, s.y_raw_px)
                            for s in frame.spots})
    rows: dict[int, list[tuple[float, float, float, float, float]]] = {}
    with truth_spots.open() as file:
        for row in csv.DictReader(file):
            key = (int(row["frame"]), int(row["laser_id"]))
            if row["visible"] == "1" and key in tracked and np.isfinite(tracked[key][0]):
                rows.setdefault(key[1], []).append(
                    (float(row["time_s"]), float(row["x_exposure_px"]),
                     float(row["y_exposure_px"]), *tracked[key]))
    gains = []
    for laser_id, samples in sorted(rows.items()):
        table = np.array(samples)
        result = []
        for start, stop in ((kick_s, kick_s + EARLY_S), (end_s - LATE_S, end_s)):
            part = table[(table[:, 0] >= start) & (table[:, 0] < stop)]
            true = part[:, 1:3] - part[:, 1:3].mean(axis=0)
            measured = part[:, 3:5] - part[:, 3:5].mean(axis=0)
            result.append((float(np.sum(measured * true) / np.sum(true * true)),
                           float(np.sqrt(np.mean(np.sum(true * true, axis=1))))))
        gains.append((laser_id, result[1][1], result[0][0], result[1][0]))
    return gains


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", type=Path,
                        default=REPO / "config" / "scenarios" / "ground_kick.yaml")
    parser.add_argument("--rates", nargs="+", default=["lossless", "60", "crf18"])
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--out", type=Path, default=Path("/tmp/bench_codec_damping"))
    args = parser.parse_args()
    scenario = load_scenario(args.scenario)
    if args.seed is not None:
        scenario = replace(scenario, seed=args.seed)
    rendered = args.out / "rendered"
    if not (rendered / "video.mp4").exists():
        simulate(scenario, rendered, codec="lossless", progress=False)
    truth = truth_from_run(rendered / "truth" / "run.json")
    sds = str(Path(sys.executable).with_name("sds"))
    for rate in args.rates:
        folder = args.out / rate
        folder.mkdir(parents=True, exist_ok=True)
        video = folder / "video.mp4"
        if not video.exists() and rate == "lossless":
            video.symlink_to(rendered / "video.mp4")
        elif not video.exists():
            encode(rendered / "video.mp4", rate, video, scenario.fps)
        mbit_s = video.stat().st_size * 8 / scenario.duration_s / 1e6
        results = folder / "results"
        if not (results / "analysis.json").exists():
            subprocess.run([sds, "process", "--video", str(video), "--rig",
                            str(scenario.rig_file), "--out", str(results)], check=True,
                           capture_output=True)
        print(f"\n{rate}: {mbit_s:.1f} Mbit/s")
        gains = spot_gains(video, scenario.rig_file, rendered / "truth" / "spots.csv",
                           scenario.kick_s, scenario.duration_s)
        least = sorted(gains, key=lambda g: g[1])[:6]
        print("  spots moving least: id, late motion px RMS, gain early, gain late: "
              + "; ".join(f"{i} {m:.2f} {e:.3f} {late:.3f}" for i, m, e, late in least))
        print(f"  all spots: gain early median {np.median([g[2] for g in gains]):.4f}, "
              f"late median {np.median([g[3] for g in gains]):.4f}")
        analysis = json.loads((results / "analysis.json").read_text())
        for mode in analysis["modes"]:
            pencil = next((e for e in mode["estimates"] if e["method"] == "matrix_pencil"),
                          None)
            if pencil is None or mode["mode"] not in truth or pencil["damping_ratio"] is None:
                continue
            true_hz, true_zeta = truth[mode["mode"]]
            zeta, sigma = pencil["damping_ratio"], pencil["damping_ratio_sigma"]
            print(f"  {mode['mode']:15s} f {pencil['frequency_hz']:.4f} Hz (truth "
                  f"{true_hz:.4f})  zeta {zeta:.5f} +- {sigma:.5f} (truth {true_zeta:.5f}: "
                  f"{100 * (zeta / true_zeta - 1):+.1f} %, {(zeta - true_zeta) / sigma:+.1f} "
                  "sigma)")


if __name__ == "__main__":
    main()
