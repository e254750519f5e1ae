"""Frame-path benchmark: decode-only vs decode + publish + receive of a 4K 30 fps H.264 clip.

Usage: python bench/frame_path.py [--seconds 10] [--out DIR]
Prints a table of throughput (fps), its ratio to decode-only measured in the same run, and
stamp-to-receipt latency for real-time pacing. Node processes run under the project launcher
with the graph environment (LARGE_DATA transport, malloc thresholds).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from fractions import Fraction
from pathlib import Path

import numpy as np
from sds_bringup.launcher import Launcher
from sds_bringup.ros_env import graph_environment, pick_domain_id
from sds_camera.frame_source import Region, VideoFileSource, select
from sds_camera.video_writer import VideoWriter
from sds_ros.graph_file import apply_overrides, composed, load_graph

REPO = Path(__file__).resolve().parents[1]
GRAPH = REPO / "config" / "graphs" / "camera_monitor.yaml"
WIDTH, HEIGHT, FPS = 3840, 2160, Fraction(30)
CONTAINER_ROI = [1185, 345, 1470, 1470]  # the container's 1470x1470 px around the image centre


def write_clip(path: Path, seconds: float) -> int:
    """A 4K clip like the rig's: dim textured background, 20 moving red spots."""
    count = int(seconds * FPS)
    rng = np.random.default_rng(0)
    background = rng.integers(5, 25, (HEIGHT, WIDTH, 3), dtype=np.uint8)
    angles = np.linspace(0, 2 * np.pi, 20, endpoint=False)
    yy, xx = np.mgrid[-10:11, -10:11]
    with VideoWriter(path, WIDTH, HEIGHT, FPS, crf=20) as writer:
        for index in range(count):
            frame = background.copy()
            radius = 600 + 40 * np.sin(2 * np.pi * 2.78 * index / float(FPS) + angles)
            for x, y in zip(1920 + radius * np.cos(angles), 1080 + radius * np.sin(angles),
                            strict=True):
                spot = 230 * np.exp(-((xx - (x % 1)) ** 2 + (yy - (y % 1)) ** 2) / 18.0)
                window = frame[int(y) - 10 : int(y) + 11, int(x) - 10 : int(x) + 11, 2]
                np.maximum(window, spot.astype(np.uint8), out=window)
            writer.write(frame)
    return count


def decode_only(clip: Path, region: list[int] | None, channel: str) -> float:
    """Frames per second of decoding (and selecting region and channel) in this process."""
    source = VideoFileSource(clip)
    box = Region(*region) if region else Region.full(source.width, source.height)
    count = 0
    start = time.perf_counter()
    for frame in source.frames():
        select(frame.image, box, channel)
        count += 1
    return count / (time.perf_counter() - start)


def through_graph(clip: Path, out: Path, pacing: str, region: list[int] | None, channel: str,
                  compose: bool) -> dict:
    """Run camera -> monitor on the clip; return the monitor's summary."""
    summary = out / f"summary_{pacing}_{channel}_{int(compose)}.json"
    summary.unlink(missing_ok=True)
    overrides = [f"camera.source={clip}", f"camera.pacing={pacing}", f"camera.channel={channel}",
                 f"monitor.summary_path={summary}"]
    if region:
        overrides.append(f"camera.roi={region}")
    entries = apply_overrides(load_graph(GRAPH), overrides)
    entries = composed(entries) if compose else entries
    with open(out / "graph.log", "a") as log:
        Launcher(entries, graph_environment(pick_domain_id()), output=log).run()
    return json.loads(summary.read_text())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--out", type=Path, default=None, help="keep the clip and logs here")
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="sds-bench-"))
    out.mkdir(parents=True, exist_ok=True)
    clip = out / "bench_4k30.mp4"
    started = time.perf_counter()
    frames = write_clip(clip, args.seconds)
    print(f"clip: {frames} frames 3840x2160 H.264 at 30 fps, written in "
          f"{time.perf_counter() - started:.0f} s ({clip})\n")
    cases = [
        ("4K bgr8, 2 processes", None, "bgr", False),
        ("4K bgr8, composed", None, "bgr", True),
        ("1470x1470 red mono8, 2 processes", CONTAINER_ROI, "red", False),
        ("1470x1470 red mono8, composed", CONTAINER_ROI, "red", True),
    ]
    print(f"{'frame path':36s} {'decode fps':>10s} {'graph fps':>10s} {'ratio':>6s} "
          f"{'frames':>7s} | {'realtime fps':>12s} {'lat. med':>9s} {'lat. p95':>9s}")
    for label, region, channel, compose in cases:
        decode_fps = decode_only(clip, region, channel)
        flood = through_graph(clip, out, "flood", region, channel, compose)
        real = through_graph(clip, out, "realtime", region, channel, compose)
        print(f"{label:36s} {decode_fps:10.1f} {flood['receive_fps']:10.1f} "
              f"{flood['receive_fps'] / decode_fps:6.2f} {flood['frames']:>3d}/{frames:<3d} | "
              f"{real['receive_fps']:12.1f} {real['latency_ms_median']:7.1f}ms "
              f"{real['latency_ms_p95']:7.1f}ms")


if __name__ == "__main__":
    main()
