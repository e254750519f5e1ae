"""`sds demo`: a short synthetic clip streamed through the graph, with a summary."""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import numpy as np
from sds_camera.frame_source import VideoFileSource
from sds_camera.video_writer import VideoWriter
from tqdm import tqdm

from sds_bringup.graph import apply_overrides, load_graph
from sds_bringup.launcher import Launcher
from sds_bringup.paths import CONFIG
from sds_bringup.ros_env import graph_environment, pick_domain_id

DEMO_GRAPH = CONFIG / "graphs" / "camera_monitor.yaml"
FPS = Fraction(30000, 1001)
WIDTH, HEIGHT = 1280, 720
ROI = [280, 0, 720, 720]


def write_demo_clip(path: Path, seconds: float) -> int:
    """Write a clip of red laser-like spots circling on a dim background; return its frames."""
    count = int(seconds * FPS)
    rows, cols = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float32)
    angles = np.linspace(0, 2 * np.pi, 20, endpoint=False)
    with VideoWriter(path, WIDTH, HEIGHT, FPS) as writer:
        for index in tqdm(range(count), desc="writing demo clip", unit="frame"):
            t = index / float(FPS)
            frame = np.full((HEIGHT, WIDTH, 3), 12, np.uint8)
            red = np.zeros((HEIGHT, WIDTH), np.float32)
            radius = 250 + 15 * np.sin(2 * np.pi * 2.78 * t + angles)
            centres = zip(640 + radius * np.cos(angles), 360 + radius * np.sin(angles), strict=True)
            for x, y in centres:
                x0, y0 = int(x) - 8, int(y) - 8
                window = np.s_[y0 : y0 + 17, x0 : x0 + 17]
                red[window] += 240 * np.exp(
                    -((cols[window] - x) ** 2 + (rows[window] - y) ** 2) / (2 * 2.5**2)
                )
            frame[:, :, 2] = np.clip(frame[:, :, 2] + red, 0, 255).astype(np.uint8)
            writer.write(frame)
    return count


def run_demo(out: Path, seconds: float) -> int:
    """Write the clip, run camera -> monitor as separate processes, print the summary."""
    out.mkdir(parents=True, exist_ok=True)
    clip = (out / "demo_clip.mp4").resolve()
    written = write_demo_clip(clip, seconds)
    decodable = VideoFileSource(clip).announced_frames
    summary_path = (out / "monitor_summary.json").resolve()
    summary_path.unlink(missing_ok=True)
    entries = apply_overrides(load_graph(DEMO_GRAPH), [
        f"camera.source={clip}",
        f"camera.roi={ROI}",
        "camera.channel=red",
        f"monitor.summary_path={summary_path}",
    ])
    domain_id = pick_domain_id()
    print(f"running the graph ({DEMO_GRAPH.name}) on ROS_DOMAIN_ID={domain_id}")
    code = Launcher(entries, graph_environment(domain_id)).run()
    if not summary_path.is_file():
        print("demo failed: the monitor wrote no summary")
        return code or 1
    summary = json.loads(summary_path.read_text())
    print(f"\nSDS demo summary ({out}/)")
    print(f"  clip:             {clip.name}, {written} frames written, {decodable} in the file")
    shape = "x".join(map(str, summary["shape"]))
    print(f"  received:         {summary['frames']} frames, {shape} {summary['encoding']}")
    print(f"  receive rate:     {summary['receive_fps']:.2f} fps (video at {float(FPS):.2f})")
    print(f"  latency:          median {summary['latency_ms_median']:.1f} ms, "
          f"p95 {summary['latency_ms_p95']:.1f} ms")
    print(f"  out of order:     {summary['out_of_order']}")
    complete = summary["frames"] == decodable and summary["out_of_order"] == 0
    print("  result:           " + ("every frame arrived in order" if complete else "FRAMES LOST"))
    return code or (0 if complete else 1)
