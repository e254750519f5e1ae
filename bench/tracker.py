"""Tracker benchmark: tracking time per 4K frame against decoding time per frame, same run.

Usage: python bench/tracker.py [--seconds 3] [--out DIR]
Simulates a ground test at 3840x2160 (H.264), decodes it with the frame source's region and
channel selection (the container's region, red), then tracks the decoded frames; prints both
times per frame (tracking from the second frame on; the set-up, which compiles or loads the
numba kernels, and the first frame's acquisition are printed apart), their ratio (target:
tracking under 10 % of decoding), and the accuracy.
"""

from __future__ import annotations

import argparse
import csv
import tempfile
import time
from pathlib import Path

import numpy as np
from sds_camera.frame_source import Region, VideoFileSource
from sds_sim.scenario import load_scenario
from sds_sim.simulate import simulate
from sds_tracker.tracker import FrameTracker, is_lost

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="sds-bench-tracker-"))
    scenario = load_scenario(REPO / "config" / "scenarios" / "ground_kick.yaml",
                             {"duration_s": args.seconds})
    output = simulate(scenario, out, progress=False)
    rig = scenario.rig
    x, y, w, h = rig.container_region_px(rig.camera)
    region = Region(x, y, w, h)
    frames, start = [], time.perf_counter()
    for frame in VideoFileSource(output.video).frames(region, "red"):
        frames.append(frame.image)
    decode_s = (time.perf_counter() - start) / len(frames)
    start = time.perf_counter()
    tracker = FrameTracker(rig)
    setup_s = time.perf_counter() - start
    start = time.perf_counter()
    outputs = tracker.process(0, frames[0], (x, y))[0]
    first_s = time.perf_counter() - start
    start = time.perf_counter()
    for index, red in enumerate(frames[1:], start=1):
        outputs += tracker.process(index, red, (x, y))[0]
    track_s = (time.perf_counter() - start) / (len(frames) - 1)
    outputs += tracker.flush()
    with output.spots.open() as file:
        truth = {(int(r["frame"]), int(r["laser_id"])): r for r in csv.DictReader(file)}
    errors = np.array([[s.x_px - float(truth[(f, s.laser_id)]["x_exposure_px"]),
                        s.y_px - float(truth[(f, s.laser_id)]["y_exposure_px"])]
                       for f, spots in outputs for s in spots if not is_lost(s)])
    print(f"{len(frames)} frames 3840x2160 H.264, region {w}x{h} red")
    print(f"decode (with region and channel): {decode_s * 1e3:7.2f} ms/frame")
    print(f"tracker set-up (paths, compiled kernels): {setup_s * 1e3:.0f} ms; "
          f"first frame (acquisition on the paths): {first_s * 1e3:.0f} ms")
    print(f"tracking (20 spots + line):       {track_s * 1e3:7.2f} ms/frame")
    print(f"ratio tracking / decoding:        {track_s / decode_s:7.2f}  (target < 0.10)")
    print(f"spot error against the truth:     {np.sqrt(np.mean(errors**2)):7.3f} px RMS "
          f"over {len(errors)} spots")


if __name__ == "__main__":
    main()
