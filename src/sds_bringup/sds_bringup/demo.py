"""`sds demo` and `sds run`: the whole measuring chain as real node processes, then the analysis.

The graph is config/graphs/drop.yaml (frame source → tracker → reconstruction, recorder) plus
arduino.yaml (the serial bridge), and view.yaml (a live Rerun viewer) where there is a display.
The Rerun file is written from the recording once the graph is done: complete, where the live
viewer's best-effort subscriptions may skip frames. The demo simulates a drop, feeds the
simulator's Arduino stream through a pseudo-terminal, and compares the analysis with the
simulator's truth.
"""

from __future__ import annotations

import csv
import os
import sys
import threading
import time
import tty
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from sds_arduino.replay import paced
from sds_model.rig import Rig, load_rig
from sds_recon.results import ResultsWriter, load_results
from sds_sim.scenario import load_scenario
from sds_sim.simulate import simulate
from sds_sloshing.analysis import AnalysisOptions
from sds_sloshing.report import summary_lines, truth_from_run
from sds_sloshing.surface_series import RecordingError
from sds_viz.from_mcap import mcap_to_rrd
from tqdm import tqdm

from sds_bringup.graph import apply_overrides, load_graph
from sds_bringup.launcher import Launcher
from sds_bringup.offline import RunTables, export_recording, finish_analysis
from sds_bringup.paths import CONFIG
from sds_bringup.ros_env import graph_domain_id, graph_environment

DEMO_SCENARIO = CONFIG / "scenarios" / "drop_4p7s.yaml"
GRAPHS = ("drop.yaml", "arduino.yaml", "view.yaml")
IDLE_TIMEOUT_S = 60.0
LED_ROI_HALF_PX = 12
BRIDGE_OPEN_S = 0.5
"""The bridge opens its port within this of publishing (it reads from its start)."""


@dataclass(frozen=True)
class RunOutputs:
    """Where a run put its files, and how its graph ended."""

    recording: Path
    rerun: Path
    log: Path
    exit_code: int = 0
    failure: str | None = None
    """The needed node that failed and why (None if none did)."""


def live_view() -> bool:
    """Whether a live viewer can be shown (a display)."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def graph_entries(overrides: list[str], viewer: bool):
    """The chain: drop.yaml and arduino.yaml, with view.yaml if `viewer`, with overrides (the
    viewer's are left out without it)."""
    graphs = GRAPHS if viewer else tuple(g for g in GRAPHS if g != "view.yaml")
    entries = [e for name in graphs for e in load_graph(CONFIG / "graphs" / name)]
    return apply_overrides(entries, [o for o in overrides
                                     if viewer or not o.startswith("viewer.")])


def run_graph(overrides: list[str], out: Path, expected_frames: int | None,
              serial_lines: list[bytes] | None = None, port: Path | None = None) -> RunOutputs:
    """Run the chain until `expected_frames` fits were made (or Ctrl-C for a live camera),
    with a progress bar; node logs go to out/graph.log. The recorder refuses an existing
    recording unless the overrides say `recorder.overwrite=true`."""
    outputs = RunOutputs(out / "recording.mcap", out / "recording.rrd", out / "graph.log")
    domain_id = graph_domain_id(None)
    environment = graph_environment(domain_id)
    os.environ.update(environment)
    # The camera waits for tracker and recorder; the tracker for reconstruction, recorder and
    # the progress bar; the reconstruction and the running sloshing estimates for the
    # recorder (the fits also for the sloshing node); each for the live viewer too if any.
    viewer = live_view()
    extra = int(viewer)
    entries = graph_entries([*overrides, f"recorder.output={outputs.recording.resolve()}",
                             "viewer.spawn=true", f"camera.wait_for_subscribers={2 + extra}",
                             f"tracker.wait_for_consumers={3 + extra}",
                             f"recon.wait_for_consumers={1 + extra}",
                             f"recon.wait_for_fit_consumers={2 + extra}",
                             f"sloshing.wait_for_consumers={1 + extra}"], viewer)
    cable = plug_in(port) if serial_lines is not None and port is not None else None
    with outputs.log.open("w") as log:
        launcher = Launcher(entries, environment, output=log, console=sys.stderr)
        unplug, feeding = threading.Event(), threading.Event()
        watcher = threading.Thread(target=_watch, args=(launcher, expected_frames, serial_lines,
                                                        cable, unplug, feeding), daemon=True)
        print(f"running the graph on ROS_DOMAIN_ID={domain_id}: "
              + ", ".join(e.name for e in entries) + f" (log: {outputs.log})")
        exit_code = launcher.run(on_started=watcher.start)
        unplug.set()   # the stand-in Arduino leaves after the bridge
        watcher.join(timeout=5.0)
    if cable is not None and not feeding.is_set():
        for fd in cable:
            os.close(fd)
    if port is not None:
        port.unlink(missing_ok=True)   # the stand-in cable's link dangles once it is gone
    return replace(outputs, exit_code=exit_code, failure=launcher.failure)


def _watch(launcher: Launcher, expected_frames: int | None, serial_lines: list[bytes] | None,
           cable: tuple[int, int] | None, unplug: threading.Event,
           feeding: threading.Event) -> None:
    """Count the tracked frames (progress bar), feed the Arduino stream, stop the graph."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from sds_ros.qos import stream_qos

    from sds_msgs.msg import LaserSpotArray

    context = rclpy.Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)
    node = Node("demo_progress", context=context)
    executor.add_node(node)
    tracked: list[int] = []   # frames tracked (the tracker waits for this subscriber too)
    node.create_subscription(LaserSpotArray, "/tracker/spots",
                             lambda msg: tracked.append(msg.frame_index), stream_qos(100))
    bar = tqdm(total=expected_frames, desc="frames", unit="frame")
    written = threading.Event()
    try:
        if cable is not None and serial_lines is not None:
            # The stand-in Arduino starts with the video, as on the rig: once the bridge has
            # opened the port (opening discards what waited in it) and the first frame is in.
            while not launcher.stopping and not (node.count_publishers("/arduino/imu")
                                                 and tracked):
                executor.spin_once(timeout_sec=0.05)
            time.sleep(BRIDGE_OPEN_S)
            feeding.set()
            threading.Thread(target=feed_serial, args=(cable, serial_lines, written, unplug),
                             daemon=True).start()
        last, last_change = 0, time.monotonic()
        while not launcher.stopping:
            executor.spin_once(timeout_sec=0.1)
            if len(tracked) != last:
                bar.update(len(tracked) - last)
                last, last_change = len(tracked), time.monotonic()
            done = expected_frames is not None and last >= expected_frames and (
                not feeding.is_set() or written.is_set())
            stalled = expected_frames is not None and \
                time.monotonic() - last_change > IDLE_TIMEOUT_S
            if done or stalled:
                time.sleep(2.0)   # reconstruction, recorder and viewer finish the last frames
                break
    finally:
        bar.close()
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.shutdown(context=context)
        launcher.request_stop()


def plug_in(port: Path) -> tuple[int, int]:
    """A pseudo-terminal (raw) whose slave is linked at `port`: the stand-in Arduino's cable."""
    master, slave = os.openpty()
    tty.setraw(slave)
    port.unlink(missing_ok=True)
    port.symlink_to(os.ttyname(slave))
    return master, slave


def feed_serial(cable: tuple[int, int], lines: list[bytes], written: threading.Event,
                unplug: threading.Event) -> None:
    """A stand-in Arduino: the lines on the pseudo-terminal, in device time; `written` is set
    after the last, and it stays plugged in until `unplug` is set."""
    master, slave = cable
    for line in paced(lines):
        os.write(master, line)
    written.set()
    unplug.wait()
    os.close(master)
    os.close(slave)


def height_errors(truth_spots: Path, points: np.ndarray) -> np.ndarray:
    """Measured minus true height [mm] of every spot point with a truth."""
    truth = {}
    with truth_spots.open() as file:
        for row in csv.DictReader(file):
            if row["visible"] == "1":
                truth[(int(row["frame"]), int(row["laser_id"]))] = float(row["Z_mm"])
    return np.array([p["Z_mm"] - truth[(int(p["frame"]), int(p["laser_id"]))]
                     for p in points if (int(p["frame"]), int(p["laser_id"])) in truth])


def analyse_run(recording: Path, rig: Rig, out: Path, options: AnalysisOptions,
                truth_run: Path | None = None, overwrite: bool = True) -> dict[str, Any]:
    """Result files, the Rerun file (from the recording: every frame), the analysis report
    (`sds export`'s, in two reads of the recording); the results as a dictionary. The run's
    own folder: an earlier run's results are replaced (the caller checked `overwrite`)."""
    mcap_to_rrd(recording, recording.with_suffix(".rrd"), rig)
    tables = RunTables(ResultsWriter(out / "results", overwrite), rig)
    export_recording(recording, rig, tables)
    truth = truth_from_run(truth_run) if truth_run else None
    analysis = finish_analysis(tables, str(recording), out / "analysis", options, truth)
    if analysis.results is None:
        raise RecordingError(analysis.note)
    if analysis.note:
        print(f"sds: {analysis.note}")
    return analysis.results


def run_demo(out: Path, seconds: float | None) -> int:
    """Simulate a drop, run the whole chain on it, analyse, print the summary."""
    out.mkdir(parents=True, exist_ok=True)
    overrides = {} if seconds is None else {"duration_s": seconds}
    scenario = load_scenario(DEMO_SCENARIO, overrides)
    print(f"simulating '{scenario.name}': {scenario.duration_s:g} s, {scenario.frame_count} "
          f"frames at 3840x2160")
    simulation = simulate(scenario, out / "simulation")
    rig = scenario.rig
    led_x, led_y = (int(v) for v in scenario.events.led_position_px)
    half = LED_ROI_HALF_PX
    port = (out / "ttyARDUINO").resolve()
    serial_lines = simulation.serial.read_bytes().splitlines(keepends=True)
    # The watcher ends the demo's graph once every frame and the Arduino's last line are in.
    outputs = run_graph(["recorder.overwrite=true", "camera.linger_s=60.0",
                         f"camera.source={simulation.video.resolve()}",
                         f"camera.roi={list(rig.container_region_px(rig.camera))}",
                         f"camera.camera_model={scenario.rig.camera_file}",
                         f"camera.led_roi={[led_x - half, led_y - half, 2 * half, 2 * half]}",
                         f"tracker.rig={scenario.rig_file.resolve()}",
                         f"recon.rig={scenario.rig_file.resolve()}",
                         f"viewer.rig={scenario.rig_file.resolve()}",
                         f"arduino.port={port}"],
                        out, scenario.frame_count, serial_lines, port)
    if outputs.failure or not outputs.recording.is_file():
        print(f"demo failed: {outputs.failure or 'no recording'} (see {outputs.log})",
              file=sys.stderr)
        return outputs.exit_code or 1
    result = analyse_run(outputs.recording, rig, out,
                         AnalysisOptions(gravity_m_s2=scenario.gravity), simulation.run)
    return print_summary(out, scenario, simulation, outputs, result)


def print_summary(out: Path, scenario, simulation, outputs: RunOutputs, result: dict) -> int:
    """The demo's summary: files, modes against the truth, heights, spots, the Arduino."""
    results = load_results(out / "results")
    spots, points = results.spots, results.points
    if spots is None or points is None:
        print(f"demo failed: no spots or points in {out / 'results'}", file=sys.stderr)
        return 1
    frames = len(set(spots["frame"].tolist()))
    errors = height_errors(simulation.spots, points[points["laser_id"] != 65535])
    log = outputs.log.read_text()
    arduino = [line for line in log.splitlines() if "final: records" in line]
    offset = [line.split("LED offset ")[1] for line in log.splitlines() if "LED offset" in line]
    print(f"\nSDS demo: '{scenario.name}', {scenario.frame_count} frames "
          f"({scenario.duration_s:g} s at {scenario.fps:g} fps, 3840x2160)")
    print(f"  recording (MCAP)   {outputs.recording}")
    print(f"  Rerun              {outputs.rerun}   (open: rerun {outputs.rerun.name})")
    print(f"  report             {out / 'analysis' / 'report.html'}")
    print(f"  result files       {out / 'results'}/ (spots, points, line, fits, imu, tof .csv)")
    print(f"  frames processed   {frames} of {scenario.frame_count}")
    print(f"  heights            RMSE {np.sqrt(np.mean(errors**2)):.3f} mm against the truth "
          f"({len(errors)} points)")
    flags = {name: int(np.sum(spots["flags"] & bit != 0)) for name, bit in (
        ("lost", 1), ("saturated", 2), ("reflection suspected", 4), ("off path", 8),
        ("Hampel-replaced", 16))}
    print(f"  spots              {len(spots)} ({len(spots) // max(frames, 1)} per frame): "
          + ", ".join(f"{count} {name}" for name, count in flags.items()))
    if arduino:
        print(f"  Arduino            {arduino[-1].split('final: ')[1]}")
    if offset:
        print(f"  clocks             camera vs Arduino, from the sync LED: {offset[-1]}")
    print("  sloshing (the report has every method; errors against the simulator's truth):")
    for line in summary_lines(result):
        if any(key in line for key in ("matrix_pencil", " tof ", "no oscillation", "note:")):
            print(f"    {line}")
    complete = frames == scenario.frame_count
    print("  result             " + ("every frame measured" if complete else "FRAMES MISSING"))
    return 0 if complete else 1


def run_live(source: str, rig_file: Path, out: Path, port: str | None,
             gravity: float | None, overwrite: bool = False) -> int:
    """`sds run`: a video file or a camera through the whole chain, then the analysis (the
    caller checked `overwrite` against an earlier run in `out`)."""
    out.mkdir(parents=True, exist_ok=True)
    rig = load_rig(rig_file)
    overrides = [f"recorder.overwrite={str(overwrite).lower()}", f"camera.source={source}",
                 f"camera.roi={list(rig.container_region_px(rig.camera))}",
                 f"tracker.rig={rig_file.resolve()}", f"recon.rig={rig_file.resolve()}",
                 f"viewer.rig={rig_file.resolve()}"]
    if rig.camera_file is not None:   # the recorded camera_model then carries the intrinsics
        overrides.append(f"camera.camera_model={rig.camera_file}")
    if port:
        overrides.append(f"arduino.port={port}")
    is_file = Path(source).is_file()
    frames = None
    if is_file:
        from sds_camera.frame_source import VideoFileSource

        frames = VideoFileSource(Path(source)).announced_frames
    outputs = run_graph(overrides, out, frames)
    if outputs.failure or not outputs.recording.is_file():
        print(f"sds run: {outputs.failure or 'no recording'} (see {outputs.log})",
              file=sys.stderr)
        return outputs.exit_code or 1
    result = analyse_run(outputs.recording, rig, out, AnalysisOptions(gravity_m_s2=gravity))
    print(f"\nSDS run: {source}\n  recording {outputs.recording}\n  Rerun {outputs.rerun}\n"
          f"  report {out / 'analysis' / 'report.html'}\n  results {out / 'results'}/")
    for line in summary_lines(result):
        print(f"    {line}")
    return 0
