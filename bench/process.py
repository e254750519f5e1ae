"""Offline processing against decoding: `sds process` and `sds export` wall time as ratios.

Usage: python bench/process.py [--scenario drop_9p3s_catapult] [--runs 3] [--out DIR]
Simulates the scenario at 3840x2160 (H.264), then, `--runs` times each, side by side:
FFmpeg's own command decoding the video to nothing (no conversion: the floor), decoding the
video alone (the frame source with the container's region and red channel, as `sds process`
reads it), `sds process --video` on it (new process, imports included), reading
the recording that `sds process --mcap` and `sds export` read, and `sds export`. Prints each
run's wall and CPU times, their medians, the ratios process / decode and export / read
(issue 20's goal: 1.2 or less) and the least ratio each one's CPU time allows on this
machine's cores.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from imageio_ffmpeg import get_ffmpeg_exe

REPO = Path(__file__).resolve().parents[1]
SDS = str(Path(sys.executable).with_name("sds"))
DECODE = """
import sys
from sds_camera.frame_source import Region, VideoFileSource
from sds_model.rig import load_rig
rig = load_rig(sys.argv[2])
region = Region(*rig.container_region_px(rig.camera))
print(sum(1 for _ in VideoFileSource(sys.argv[1]).frames(region, "red")))
"""
READ = """
import sys
from sds_record.mcap_files import decoded_messages
print(sum(1 for _ in decoded_messages(sys.argv[1])))
"""


def timed(command: list[str]) -> tuple[float, float]:
    """Wall and CPU time [s] (children included) of one command in a new process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, env=dict(os.environ))
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="drop_9p3s_catapult")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="sds-bench-process-"))
    from sds_sim.scenario import load_scenario
    from sds_sim.simulate import simulate

    scenario = load_scenario(REPO / "config" / "scenarios" / f"{args.scenario}.yaml")
    video = out / "sim" / "video.mp4"
    if not video.is_file():
        simulate(scenario, out / "sim", progress=False)
    rig = str(scenario.rig_file)
    recording = out / "recording.mcap"
    times: dict[str, list[tuple[float, float]]] = {k: [] for k in
                                                   ("ffmpeg", "decode", "process", "read",
                                                    "export")}
    for run in range(args.runs):
        times["ffmpeg"].append(timed([get_ffmpeg_exe(), "-v", "error", "-i", str(video),
                                      "-f", "null", "-"]))
        times["decode"].append(timed([sys.executable, "-c", DECODE, str(video), rig]))
        times["process"].append(timed([SDS, "process", "--video", str(video), "--rig", rig,
                                       "--out", str(out / f"process_{run}"), "--no-progress",
                                       "--overwrite"]))
        if not recording.is_file():   # the graph's recording of the same video
            subprocess.run([SDS, "run", "--video", str(video), "--rig", rig, "--out",
                            str(out / "run")], check=True, stdout=subprocess.DEVNULL,
                           stderr=subprocess.DEVNULL)
            (out / "run" / "recording.mcap").rename(recording)
        times["read"].append(timed([sys.executable, "-c", READ, str(recording)]))
        times["export"].append(timed([SDS, "export", str(recording), "--rig", rig, "--out",
                                      str(out / f"export_{run}"), "--overwrite"]))
    print(f"{scenario.name}: {scenario.frame_count} frames 3840x2160 H.264, {args.runs} runs")
    medians = {}
    for name, runs in times.items():
        medians[name] = statistics.median(wall for wall, _ in runs)
        walls = ", ".join(f"{wall:.2f}" for wall, _ in runs)
        cpus = ", ".join(f"{cpu:.2f}" for _, cpu in runs)
        print(f"  {name:<8} wall {walls} s (median {medians[name]:.2f}), CPU {cpus} s")
    print(f"  process / decode {medians['process'] / medians['decode']:.2f}   "
          f"process / ffmpeg {medians['process'] / medians['ffmpeg']:.2f}   "
          f"export / read {medians['export'] / medians['read']:.2f}   (goal: 1.2 or less)")
    # Wall time is at least CPU time / cores, however well the work overlaps.
    cores = len(os.sched_getaffinity(0))
    for name, base in (("process", "decode"), ("export", "read")):
        cpu = statistics.median(c for _, c in times[name])
        print(f"  {name}'s CPU {cpu:.2f} s on {cores} cores: {cpu / cores:.2f} s of wall time "
              f"at least, {cpu / cores / medians[base]:.2f} x {base} at best")


if __name__ == "__main__":
    main()
