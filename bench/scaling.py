"""How cost grows: the offline and live paths against length, frame size, diodes and line rows.

Usage: python bench/scaling.py [--out DIR] [--lengths 10 60 600] [--seconds 10]

Simulates `--seconds` of the 1 g ground kick (H.264) for each rig: the StELIUM rig at 1080p,
4K and 5.3K (its camera scaled to 1920x1080, 3840x2160, 5312x2988), and at 4K with 60 and 120
diodes (a hexagonal head) and without the line laser. The longer recordings are the 4K clip
repeated (FFmpeg's concat, no re-encoding). Each measurement runs in a new process:
- offline: `sds process --video` (tracking, reconstruction, result files, analysis, report),
  wall time and peak resident memory; decoding the same video alone for the ratio;
- live: the per-frame pipeline the nodes' code forms (sds_workflows.pipeline.FramePipeline:
  tracker, frame_points and InstantFits, reconstruct_line, with drop.yaml's parameters) on
  each decoded frame, ms per frame (median, p95) and the process's peak resident memory.
Then it fits how each dimension's cost grows above its smallest case, cost − cost₀ ∝
(x − x₀)^b (b = 1: linear), and prints the table.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SDS = str(Path(sys.executable).with_name("sds"))
SCENARIO = REPO / "config" / "scenarios" / "ground_kick.yaml"
SIZES = {"1080p": 0.5, "4K": 1.0, "5.3K": 5312 / 3840}
DIODES = (60, 120)
DECODE = """
import sys
from sds_camera.frame_source import Region, VideoFileSource
from sds_model.rig import load_rig
rig = load_rig(sys.argv[2])
region = Region(*rig.container_region_px(rig.camera))
print(sum(1 for _ in VideoFileSource(sys.argv[1]).frames(region, "red")))
"""
SIMULATE = """
import sys
from pathlib import Path
from sds_sim.scenario import load_scenario
from sds_sim.simulate import simulate
scenario = load_scenario(Path(sys.argv[1]), {"duration_s": float(sys.argv[3]), "rig": sys.argv[2]})
simulate(scenario, Path(sys.argv[4]), progress=False)
"""
LIVE = """
import json, sys, time
from pathlib import Path
import numpy as np
from sds_model.rig import load_rig
from sds_workflows.pipeline import FramePipeline, video_frames
rig = load_rig(sys.argv[2])
pipeline = FramePipeline(rig)
times, rows = [], []
for frame in video_frames(Path(sys.argv[1]), rig):
    start = time.perf_counter()
    step = pipeline.process(frame)
    times.append(time.perf_counter() - start)
    rows.append(int(np.isfinite(step.line.line.x_px).sum()))
times = np.array(times[10:]) * 1e3
print(json.dumps({"median_ms": float(np.median(times)), "p95_ms": float(np.percentile(times, 95)),
                  "frames": len(times) + 10, "line_rows": float(np.median(rows))}))
"""


@dataclass(frozen=True)
class Case:
    """One recording to measure: its dimension, the value along it, the video and its rig."""

    dimension: str
    value: float
    label: str
    video: Path
    rig_file: Path


@dataclass(frozen=True)
class Measured:
    """What one case cost."""

    decode_s: float
    process_s: float
    process_mb: float
    live_median_ms: float
    live_p95_ms: float
    live_mb: float
    frames: int
    line_rows: float


def run(command: list[str]) -> tuple[float, float, str]:
    """Wall time [s], peak resident memory [MB] and stdout of one command in a new process."""
    start = time.perf_counter()
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                               text=True, env=dict(os.environ))
    stdout = process.stdout.read() if process.stdout else ""
    _, status, usage = os.wait4(process.pid, 0)
    process.returncode = os.waitstatus_to_exitcode(status)
    if process.returncode != 0:
        raise RuntimeError(f"{command[:3]} failed with exit code {process.returncode}")
    return time.perf_counter() - start, usage.ru_maxrss / 1024, stdout


def hexagonal_head(rig, count: int, spacing_mm: float = 7.0):
    """The rig with `count` vertical beams on a hexagonal grid, nearest the axis first (none
    within 8 mm of it, where a beam points at the camera), emitters 10 mm below the camera."""
    from sds_model.rig import LaserDiode

    z = float(rig.camera_position_mm[2]) - 10.0
    grid = [(spacing_mm * (i + 0.5 * j), spacing_mm * np.sqrt(3) / 2 * j)
            for i in range(-12, 13) for j in range(-12, 13)]
    points = sorted((p for p in grid if 8.0 <= np.hypot(*p) <= 0.9 * rig.container.radius_mm),
                    key=lambda p: np.hypot(*p))
    if len(points) < count:
        raise ValueError(f"only {len(points)} beams fit at {spacing_mm} mm spacing")
    diodes = tuple(LaserDiode(k, 1, np.array([x, y, z]), np.array([0.0, 0.0, -1.0]))
                   for k, (x, y) in enumerate(points[:count]))
    return replace(rig, diodes=diodes)


def simulated(out: Path, name: str, rig, seconds: float) -> tuple[Path, Path]:
    """The video of the ground kick seen through `rig` (simulated once, in a new process),
    and its rig file."""
    from sds_model.rig import save_rig

    folder = out / name
    folder.mkdir(parents=True, exist_ok=True)
    rig_file = save_rig(rig, folder / "rig.yaml")
    video = folder / "sim" / "video.mp4"
    if not video.is_file():
        print(f"simulating {name} ({seconds:g} s)", flush=True)
        # Not in this process: a child inherits its parent's peak resident memory through
        # fork and exec (Linux keeps the high-water mark), so a large parent would be every
        # measurement's peak (it made all of them 799 MB once).
        subprocess.run([sys.executable, "-c", SIMULATE, str(SCENARIO), str(rig_file),
                        str(seconds), str(folder / "sim")], check=True)
    return video, rig_file


def repeated(video: Path, times: int, target: Path) -> Path:
    """The video `times` over, one file (FFmpeg's concat demuxer, streams copied)."""
    import imageio_ffmpeg

    if not target.is_file():
        listing = target.with_suffix(".txt")
        listing.write_text(f"file '{video.resolve()}'\n" * times)
        subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-f", "concat",
                        "-safe", "0", "-i", str(listing), "-c", "copy", str(target)],
                       check=True)
    return target


def cases(out: Path, seconds: float, lengths: list[float]) -> list[Case]:
    """Every recording: lengths at 4K, frame sizes, diode counts, the line laser or none."""
    from sds_model.rig import load_rig

    stelium = load_rig(REPO / "config" / "rigs" / "stelium.yaml")
    found: list[Case] = []
    base_video, base_rig = simulated(out, "4K", replace(stelium, camera_file=None), seconds)
    for length in lengths:
        count = max(1, round(length / seconds))
        video = base_video if count == 1 else repeated(base_video, count,
                                                       out / f"4K_{count}x.mp4")
        found.append(Case("length", count * seconds, f"{count * seconds:g} s", video, base_rig))
    for label, factor in SIZES.items():
        if factor == 1.0:
            video, rig_file = base_video, base_rig
        else:
            rig = replace(stelium, camera=stelium.camera.scaled(factor), camera_file=None)
            video, rig_file = simulated(out, label, rig, seconds)
        width, height = (round(v * factor) for v in (3840, 2160))
        found.append(Case("frame size", width * height / 1e6, f"{label} ({width}x{height})",
                          video, rig_file))
    found.append(Case("diodes", 20, "20", base_video, base_rig))
    for count in DIODES:
        rig = hexagonal_head(replace(stelium, camera_file=None), count)
        video, rig_file = simulated(out, f"diodes_{count}", rig, seconds)
        found.append(Case("diodes", count, str(count), video, rig_file))
    video, rig_file = simulated(out, "no_line", replace(stelium, camera_file=None,
                                                        line_laser=None), seconds)
    found.append(Case("line rows", 0, "no line laser", video, rig_file))
    found.append(Case("line rows", 1, "line laser", base_video, base_rig))
    return found


def measure(case: Case, out: Path) -> Measured:
    """Decode alone, `sds process`, and the live path's per-frame code, each in a new process."""
    rig = str(case.rig_file)
    decode_s, _, _ = run([sys.executable, "-c", DECODE, str(case.video), rig])
    results = out / "results" / case.video.parent.name / case.video.stem
    process_s, process_mb, _ = run([SDS, "process", "--video", str(case.video), "--rig", rig,
                                    "--out", str(results), "--no-progress", "--overwrite"])
    _, live_mb, stdout = run([sys.executable, "-c", LIVE, str(case.video), rig])
    live = json.loads(stdout.strip().splitlines()[-1])
    return Measured(decode_s, process_s, process_mb, live["median_ms"], live["p95_ms"], live_mb,
                    live["frames"], live["line_rows"])


def growth(xs: list[float], ys: list[float]) -> float:
    """The exponent b of the cost above the smallest case, y − y₀ ∝ (x − x₀)^b, fitted in
    log-log over the larger cases (b = 1: linear; NaN where the cost does not grow): a fixed
    cost (imports, the report) would otherwise hide how the rest grows."""
    order = np.argsort(xs)
    x, y = np.asarray(xs, float)[order], np.asarray(ys, float)[order]
    dx, dy = x[1:] - x[0], y[1:] - y[0]
    if len(dx) < 2 or np.any(dx <= 0) or np.any(dy <= 0):
        return float("nan")
    return float(np.polyfit(np.log(dx), np.log(dy), 1)[0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--seconds", type=float, default=10.0, help="each simulated clip [s]")
    parser.add_argument("--lengths", type=float, nargs="+", default=[10.0, 60.0, 600.0],
                        help="recording lengths [s] (the 4K clip repeated)")
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="sds-bench-scaling-"))
    measured = []
    for case in cases(out, args.seconds, args.lengths):
        print(f"measuring {case.dimension}: {case.label}", flush=True)
        measured.append((case, measure(case, out)))
    print(f"\n{'dimension':<11} {'value':<22} {'frames':>6} {'line rows':>9} {'decode s':>9} "
          f"{'process s':>9} {'/decode':>7} {'process MB':>10} {'live ms med':>11} "
          f"{'p95':>6} {'live MB':>8}")
    for case, m in measured:
        print(f"{case.dimension:<11} {case.label:<22} {m.frames:>6} {m.line_rows:>9.0f} "
              f"{m.decode_s:>9.2f} {m.process_s:>9.2f} {m.process_s / m.decode_s:>7.2f} "
              f"{m.process_mb:>10.0f} {m.live_median_ms:>11.2f} {m.live_p95_ms:>6.2f} "
              f"{m.live_mb:>8.0f}")
    print("\ngrowth above the smallest case, cost − cost₀ ∝ (x − x₀)^b (b = 1: linear, nan: "
          "does not grow):")
    for dimension, x_name in (("length", "recording length"), ("frame size", "pixels"),
                              ("diodes", "diodes")):
        rows = [(c, m) for c, m in measured if c.dimension == dimension]
        xs = [c.value for c, _ in rows]
        print(f"  {dimension:<10} against {x_name}: offline time b = "
              f"{growth(xs, [m.process_s for _, m in rows]):.2f} (per frame "
              f"{growth(xs, [m.process_s / m.frames for _, m in rows]):.2f}), memory b = "
              f"{growth(xs, [m.process_mb for _, m in rows]):.2f}; live per frame b = "
              f"{growth(xs, [m.live_median_ms for _, m in rows]):.2f}, memory b = "
              f"{growth(xs, [m.live_mb for _, m in rows]):.2f}")
    own_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    if any(min(m.process_mb, m.live_mb) <= own_mb for _, m in measured):
        print(f"  memory     this bench process peaked at {own_mb:.0f} MB, and a child's peak "
              "includes its parent's: peaks at or below it are upper bounds")
    lines = {c.value: m for c, m in measured if c.dimension == "line rows"}
    if len(lines) == 2:
        without, with_line = lines[0], lines[1]
        extra_ms = with_line.live_median_ms - without.live_median_ms
        print(f"  line rows  the line laser's {with_line.line_rows:.0f} rows add "
              f"{extra_ms:.2f} ms per frame live ({1e3 * extra_ms / with_line.line_rows:.2f} "
              f"µs per row) and {with_line.process_s - without.process_s:.2f} s offline over "
              f"{with_line.frames} frames")


if __name__ == "__main__":
    main()
