"""`sds demo`: a simulated ground test streamed through the graph, with a summary."""

from __future__ import annotations

import json
from pathlib import Path

from sds_camera.frame_source import VideoFileSource
from sds_sim.scenario import load_scenario
from sds_sim.simulate import simulate

from sds_bringup.graph import apply_overrides, load_graph
from sds_bringup.launcher import Launcher
from sds_bringup.paths import CONFIG
from sds_bringup.ros_env import graph_environment, pick_domain_id

DEMO_GRAPH = CONFIG / "graphs" / "camera_monitor.yaml"
DEMO_SCENARIO = CONFIG / "scenarios" / "ground_kick.yaml"
DEMO_SCALE = 0.5   # 1920x1080: the whole demo in well under a minute on 2 cores


def run_demo(out: Path, seconds: float) -> int:
    """Simulate a ground test, run camera -> monitor as separate processes, print the summary."""
    scenario = load_scenario(DEMO_SCENARIO, {"duration_s": seconds, "scale": DEMO_SCALE})
    print(f"simulating '{scenario.name}' ({seconds:g} s at {DEMO_SCALE:g} x 3840x2160)")
    simulation = simulate(scenario, out / "simulation")
    clip = simulation.video.resolve()
    written = scenario.frame_count
    decodable = VideoFileSource(clip).announced_frames
    region = scenario.rig.container_region_px(scenario.rig.camera.scaled(DEMO_SCALE))
    summary_path = (out / "monitor_summary.json").resolve()
    summary_path.unlink(missing_ok=True)
    entries = apply_overrides(load_graph(DEMO_GRAPH), [
        f"camera.source={clip}",
        f"camera.roi={list(region)}",
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
    print(f"  simulation:       {simulation.directory}/ (video, arduino/, truth/)")
    modes = ", ".join(f"{m.frequency_hz:.2f} Hz (zeta {m.damping_ratio:g})"
                      for m in scenario.mode_motions())
    print(f"  truth:            modes at {modes}")
    print(f"  clip:             {clip.name}, {written} frames written, {decodable} in the file")
    shape = "x".join(map(str, summary["shape"]))
    print(f"  received:         {summary['frames']} frames, {shape} {summary['encoding']}")
    print(f"  receive rate:     {summary['receive_fps']:.2f} fps (video at {scenario.fps:g})")
    print(f"  latency:          median {summary['latency_ms_median']:.1f} ms, "
          f"p95 {summary['latency_ms_p95']:.1f} ms")
    print(f"  out of order:     {summary['out_of_order']}")
    complete = summary["frames"] == decodable and summary["out_of_order"] == 0
    print("  result:           " + ("every frame arrived in order" if complete else "FRAMES LOST"))
    return code or (0 if complete else 1)
