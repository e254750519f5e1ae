"""Whole-graph benchmark (issue 10): a simulated 4K 30 fps drop through the measuring chain.

    .venv/bin/python bench/graph.py [--seconds 4.7] [--minutes 10] [--out /tmp/bench_graph]

Prints, measured in one run on the same file:
- decode-only fps (the frame source's own work: decode, container region, red channel);
- per-stage time per frame in one process: decode, transport (serialise the image message),
  tracking, triangulation and fits, recording (MCAP write of the image);
- whole-graph fps with `pacing: flood` (camera → tracker → reconstruction → recorder, every
  frame acknowledged; sloshing estimates) and its ratio to decode-only, with each process's
  CPU time per frame, in the process layouts of `LAYOUTS`;
- frame → PointCloud2 latency in real time (median, p95; the Hampel window's own delay of
  hampel_window // 2 frames is part of it and given apart), each layout; and frame → first
  PointCloud2 of that frame (/recon/points_live, from the spots as measured), what a live
  view receives, with the frames it never received;
- peak memory per process, and resident memory over a `--minutes` real-time run
  (frame source `repeat: 0`), with the camera's packets recorded (drop.yaml) and counted
  against those it sent, and the frames it shed while its decoder fell behind;
- `--fps` sets the camera's frame rate of the real-time runs (`camera.rate` = fps / the
  video's): a number, or `half-decode`, half the decode-only rate measured in the same run,
  so that live latency is measured where the machine can hold the rate. Latency counts from
  when each frame was played: its stamp keeps the video's time, which at a rate below 1 runs
  ahead of the clock, and the camera's origin on /camera/origin turns it into play time;
- `--low-delay`: the real-time runs decode on slice threads only (no frame held per thread);
- the stream's own reordering (how long a B-frame waits for the later frame it refers to,
  before any decoder can give it out) is measured on the file and given apart from the live
  latency; `--stream live` plays the drop as a live camera streams it instead (no B-frames,
  several slices per frame), decode-only rate included;
- with `--check-process`, one real-time play of the file beside the last `--hogs` count, then
  `sds process --mcap` on its recording against `sds process --video` on the file (the same
  spots and points: every frame the camera sent, those shed live included);
- with `--busy`, each real-time run again beside a CPU-bound process (one core's worth);
  `--hogs 1 2` runs each beside 1, then 2 of them instead (2: the chain gets less than a
  frame period of CPU per frame); the console's shedding lines come from each run's log;
- with `--lateral`, the side camera runs beside the chain (config/graphs/lateral.yaml, the
  simulator's 512x512 side view at 125 fps, in real time, repeated like the top video), and
  with `--record-images` its frames recorded are counted against those it published.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import psutil

REPO = Path(__file__).resolve().parents[1]
SCENARIO = REPO / "config" / "scenarios" / "drop_4p7s.yaml"
HAMPEL_DELAY_FRAMES = 2
LIVE_SLICES = 4
IDLE_S = 10.0
LAYOUTS = {
    "own processes": {"camera": "camera", "tracker": "tracker", "recon": "recon",
                      "recorder": "recorder"},
    "chain composed": {"camera": "chain", "tracker": "chain", "recon": "chain",
                       "recorder": "recorder"},
    "all composed": {"camera": "graph", "tracker": "graph", "recon": "graph",
                     "recorder": "graph"},
    "capture + analysis": {"camera": "capture", "tracker": "analysis", "recon": "analysis",
                           "recorder": "capture"},
}
"""Process of each node: every node in its own; camera → tracker → reconstruction in one, the
recorder apart (config/graphs/drop.yaml); all in one; camera and recorder in one, tracker and
reconstruction in another. The niced sloshing node keeps its own process in each."""


def simulate_once(out: Path, seconds: float, lateral: bool = False):
    """The drop (with the side view if `lateral`), simulated once per --out."""
    from sds_sim.scenario import load_scenario
    from sds_sim.simulate import simulate

    overrides: dict = {"duration_s": seconds}
    if lateral:
        overrides["lateral"] = {}
    scenario = load_scenario(SCENARIO, overrides)
    folder = out / ("sim_lateral" if lateral else "sim")
    video = folder / "video.mp4"
    if not video.is_file():
        simulate(scenario, folder, progress=False)
    return scenario, video


def live_stream(video: Path) -> Path:
    """The drop as a live camera streams it (x264's zerolatency: no B-frames, so no frame waits
    for a later one; `LIVE_SLICES` slices per frame, which slice threads decode side by side),
    at the file's own mean bit rate; made once per --out."""
    import av
    import imageio_ffmpeg

    live = video.with_name("live_stream.mp4")
    if live.is_file():
        return live
    with av.open(str(video)) as container:
        stream = container.streams.video[0]
        assert stream.duration is not None and stream.time_base is not None
        bit_s = round(8 * video.stat().st_size / float(stream.duration * stream.time_base))
    partial = live.with_suffix(".partial.mp4")
    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error",
                    "-i", str(video), "-c:v", "libx264", "-preset", "veryfast",
                    "-tune", "zerolatency", "-x264-params", f"slices={LIVE_SLICES}",
                    "-b:v", str(bit_s), "-maxrate", str(bit_s), "-bufsize", str(bit_s),
                    "-pix_fmt", "yuv420p", "-threads", "1", str(partial)], check=True)
    partial.rename(live)
    return live


def reorder_delays_s(video: Path, fps: float) -> np.ndarray:
    """Per frame of the file (presentation order), how long after it is played the decoder
    can first give it out [s, media time]: the stream's own reordering (a B-frame waits for
    the later frame it refers to), decoded on slice threads so that no thread holds a frame.
    NaN for the last frames, which only the end of the file (or its next repeat) lets out."""
    from sds_camera.compressed_video import PacketDecoder, VideoFilePackets

    packets = VideoFilePackets(video)
    decoder = PacketDecoder(packets.format, low_delay=True)
    delays_s = np.full(packets.announced_frames, np.nan)
    for packet in packets.packets():
        for frame in decoder.decode(packet):
            delays_s[round(frame.time_ns * 1e-9 * fps)] = (packet.due_ns - frame.time_ns) * 1e-9
    packets.close()
    return delays_s


def stage_times(video: Path, rig) -> dict[str, float]:
    """Mean ms per frame of each stage (the recorder's chunk compression comes every few
    frames), run one after the other in this process."""
    from builtin_interfaces.msg import Time
    from rclpy.serialization import serialize_message
    from sds_camera.frame_source import Region, open_source
    from sds_record.mcap_files import McapRecorder
    from sds_ros.image_msg import image_to_msg
    from sds_workflows.pipeline import FramePipeline, RedFrame

    region = Region(*rig.container_region_px(rig.camera))
    pipeline = FramePipeline(rig)
    recorder = McapRecorder(video.with_name("stages.mcap"), overwrite=True)
    recorder.add_topic("/camera/image", "sensor_msgs/msg/Image")
    times: dict[str, list[float]] = {k: [] for k in ("decode", "transport", "tracking",
                                                      "triangulation", "recording")}
    source = open_source(str(video))
    frames = source.frames(region, "red")
    while True:
        start = time.perf_counter()
        frame = next(frames, None)
        if frame is None:
            break
        red = frame.image
        times["decode"].append(time.perf_counter() - start)
        start = time.perf_counter()
        data = serialize_message(image_to_msg(red, Time(sec=frame.index), "camera"))
        times["transport"].append(time.perf_counter() - start)
        start = time.perf_counter()
        tracked = pipeline.track(RedFrame(frame.index, frame.time_ns * 1e-9, red,
                                          (region.x, region.y)))
        times["tracking"].append(time.perf_counter() - start)
        start = time.perf_counter()
        pipeline.reconstruct(tracked)
        times["triangulation"].append(time.perf_counter() - start)
        start = time.perf_counter()
        recorder.write("/camera/image", data, frame.time_ns, frame.time_ns)
        times["recording"].append(time.perf_counter() - start)
    recorder.close()
    source.close()
    return {k: 1e3 * statistics.mean(v[5:]) for k, v in times.items()}


def decode_only(video: Path, rig) -> tuple[float, float]:
    """The frame source's own work alone: frames per second, and CPU ms per frame (the
    decoder's threads included)."""
    from sds_camera.frame_source import Region, open_source

    region = Region(*rig.container_region_px(rig.camera))
    source = open_source(str(video))
    start, cpu, count = time.perf_counter(), time.process_time(), 0
    for _ in source.frames(region, "red"):
        count += 1
    source.close()
    return count / (time.perf_counter() - start), 1e3 * (time.process_time() - cpu) / count


def memory_kb(pid: int, field: str) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(field):
            return int(line.split()[1])
    return 0


def cpu_s(pid: int) -> float:
    """User + system CPU time [s] a process has used so far."""
    times = psutil.Process(pid).cpu_times()
    return times.user + times.system


def run_graph(overrides: list[str], expected: int | None, minutes: float | None,
              image_subscribers: int = 2, processes: dict[str, str] | None = None,
              log_file: Path | None = None, graphs: tuple[str, ...] = ("drop.yaml",)):
    """The drop graph with a probe on /recon/points and /recon/points_live: receipt times and
    stamps of each, memory, each process's CPU time between the first and the last cloud, and
    the camera's origin (the stamp of its media time 0, NaN if it never came) [s]."""
    from dataclasses import replace

    from sds_bringup.launcher import Launcher
    from sds_bringup.ros_env import graph_environment, pick_domain_id
    from sds_ros.graph_file import apply_overrides, load_graph

    domain = pick_domain_id()
    environment = graph_environment(domain)
    os.environ.update(environment)
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from sds_ros.qos import live_qos, stream_qos
    from sensor_msgs.msg import PointCloud2
    from std_msgs.msg import Header

    from sds_msgs.msg import LaserSpotArray

    entries = apply_overrides([e for name in graphs
                               for e in load_graph(REPO / "config" / "graphs" / name)],
                              [*overrides, f"camera.wait_for_subscribers={image_subscribers}",
                               "tracker.wait_for_consumers=3", "recon.wait_for_consumers=1"])
    entries = [replace(e, process=(processes or {}).get(e.name, e.process)) for e in entries]
    receipts: list[tuple[float, float]] = []
    live: list[tuple[float, float]] = []
    spots_live: list[tuple[float, float]] = []
    origin: list[float] = []
    memory: dict[str, list[tuple[float, int]]] = {}
    cpu: dict[str, list[float]] = {}
    # Receipts on the system clock as it read at the start, advanced by the monotonic clock:
    # the camera's stamps (its origin on the system clock plus media time) do not move when
    # the system clock steps during a run, so neither may the receipts. (A step of about
    # +23 s once read as 24 s of latency for the rest of a 10-minute run.)
    system_start_s, monotonic_start_s = time.time(), time.monotonic()

    def clock_s() -> float:
        return system_start_s + time.monotonic() - monotonic_start_s

    def sample_cpu() -> None:
        for process in launcher.processes:
            if process.popen and process.popen.poll() is None:
                cpu.setdefault(process.name, []).append(cpu_s(process.popen.pid))

    def probe() -> None:
        context = rclpy.Context()
        rclpy.init(context=context)
        node = Node("bench_probe", context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        # Subscribing to the spots too makes the tracker wait for this probe (its third
        # consumer), so the probe's cloud subscription is in place before the first cloud.
        node.create_subscription(LaserSpotArray, "/tracker/spots", lambda _: None, stream_qos())
        node.create_subscription(
            PointCloud2, "/recon/points",
            lambda m: receipts.append((clock_s(), m.header.stamp.sec
                                       + m.header.stamp.nanosec * 1e-9)), stream_qos(100))
        node.create_subscription(
            LaserSpotArray, "/tracker/spots_live",
            lambda m: spots_live.append((clock_s(), m.header.stamp.sec
                                         + m.header.stamp.nanosec * 1e-9)), live_qos())
        node.create_subscription(
            Header, "/camera/origin",
            lambda m: origin.append(m.stamp.sec + m.stamp.nanosec * 1e-9),
            QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL))
        node.create_subscription(
            PointCloud2, "/recon/points_live",
            lambda m: live.append((clock_s(), m.header.stamp.sec
                                   + m.header.stamp.nanosec * 1e-9)), live_qos())
        start, last_sample, count, last_change = time.monotonic(), 0.0, 0, 0.0
        while not launcher.stopping:
            executor.spin_once(timeout_sec=0.05)
            now = time.monotonic()
            if now - last_sample > 10.0:
                last_sample = now
                for process in launcher.processes:
                    if process.popen and process.popen.poll() is None:
                        memory.setdefault(process.name, []).append(
                            (now - start, memory_kb(process.popen.pid, "VmRSS")))
            if receipts and (len(receipts) != count or last_change == 0.0):
                if last_change == 0.0:
                    sample_cpu()
                count, last_change = len(receipts), now
            finished = expected is not None and (
                len(receipts) >= expected or (receipts and now - last_change > IDLE_S))
            if finished or (minutes is not None and now - start > minutes * 60):
                sample_cpu()
                for process in launcher.processes:
                    if process.popen and process.popen.poll() is None:
                        memory.setdefault(process.name + " peak", []).append(
                            (now - start, memory_kb(process.popen.pid, "VmHWM")))
                break
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)

    def watch() -> None:
        try:
            probe()
        finally:   # the graph stops even if the probe fails
            launcher.request_stop()

    with Path(log_file or os.devnull).open("w") as log:
        launcher = Launcher(entries, environment, output=log)
        launcher.run(on_started=threading.Thread(target=watch, daemon=True).start)
    step_s = time.time() - clock_s()
    if abs(step_s) > 0.05:
        print(f"(the system clock stepped {step_s:+.2f} s during this run; receipts are on "
              "the monotonic clock from its start)")
    per_frame = {name: 1e3 * (v[-1] - v[0]) / max(len(receipts) - 1, 1)
                 for name, v in cpu.items() if len(v) == 2}
    return receipts, live, spots_live, memory, per_frame, origin[0] if origin else np.nan


def played_s(stamp_s: float, origin_s: float, rate: float) -> float:
    """When the frame stamped `stamp_s` was played [s, system clock]: its stamp keeps the
    video's time (origin + media time), played at `rate` times real time it comes later."""
    return origin_s + (stamp_s - origin_s) / rate


def recorded_packets(recording: Path, log: Path) -> tuple[int, int | None]:
    """The camera's video packets a recording holds, and how many the camera published (its
    line when the graph stopped, in the run's log; None if it never said)."""
    import re

    from sds_record.mcap_files import message_counts

    said = re.findall(r"\[camera\]: (?:stopped|end of [^:]*): published .* and the (\d+) "
                      "video packets", log.read_text())
    return (message_counts(recording, ["/camera/video"]).get("/camera/video", 0),
            int(said[-1]) if said else None)


def recorded_frames(recording: Path, fps: float, topic: str = "/camera/image"
                    ) -> tuple[int, int]:
    """Frames a recording holds, and how many the camera published from its first to its last
    (their stamps, read from each image's CDR header, come every 1/fps: the camera never skips
    one)."""
    from sds_record.mcap_files import header_stamp_ns, read_messages

    stamps_ns = {header_stamp_ns(m.data) for m in read_messages(recording, [topic])}
    if not stamps_ns:
        return 0, 0
    return len(stamps_ns), round((max(stamps_ns) - min(stamps_ns)) * 1e-9 * fps) + 1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=4.7)
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--out", type=Path, default=Path("/tmp/bench_graph"))
    parser.add_argument("--in-flight", type=int, default=2,
                        help="frames the flooding source may have unacknowledged")
    parser.add_argument("--layouts", nargs="+", choices=list(LAYOUTS), default=list(LAYOUTS),
                        help="which process layouts to measure")
    parser.add_argument("--hogs", type=int, nargs="+", default=None,
                        help="run each real-time measurement beside this many CPU-bound "
                             "processes, for each count given (default 0; --busy: 0 1)")
    parser.add_argument("--busy", action="store_true",
                        help="also run each real-time measurement beside a CPU-bound process")
    parser.add_argument("--record-images", action="store_true",
                        help="the real-time runs record the decoded frames too, and count "
                             "them against the camera's")
    parser.add_argument("--fps", default="",
                        help="the camera's frame rate in the real-time runs [fps], or "
                             "half-decode (default: the video's)")
    parser.add_argument("--low-delay", action="store_true",
                        help="the real-time runs decode on slice threads only (camera."
                             "low_delay: no frame held per decoding thread)")
    parser.add_argument("--stream", choices=("file", "live"), default="file",
                        help="what the camera plays: the simulated file (x264 with B-frames, "
                             "one slice per frame), or the same drop as a live camera streams "
                             "it (no B-frames, LIVE_SLICES slices per frame; re-encoded, "
                             "so for latency, not for the spots)")
    parser.add_argument("--check-process", action="store_true",
                        help="also compare sds process --mcap on a real-time recording with "
                             "sds process --video on the file")
    parser.add_argument("--no-flood", action="store_true",
                        help="measure the real-time runs only")
    parser.add_argument("--lateral", action="store_true",
                        help="the real-time runs have the side camera beside the chain")
    args = parser.parse_args()
    sys.stdout.reconfigure(line_buffering=True)   # each result shows as soon as measured
    args.out.mkdir(parents=True, exist_ok=True)
    scenario, video = simulate_once(args.out, args.seconds, args.lateral)
    if args.stream == "live":
        video = live_stream(video)
    rig, rig_file = scenario.rig, scenario.rig_file.resolve()
    region = list(rig.container_region_px(rig.camera))
    base = [f"camera.source={video}", f"camera.roi={region}", f"tracker.rig={rig_file}",
            f"recon.rig={rig_file}"]
    side: list[str] = []
    side_fps = 0.0
    if args.lateral:
        from sds_lateral.view import load_lateral_view

        view = load_lateral_view(scenario.lateral.view_file)
        side_fps = view.fps
        side = [f"lateral.source={video.parent / 'lateral' / 'video.mp4'}", "lateral.repeat=0",
                f"lateral.camera_model={view.camera_file}",
                f"lateral.wait_for_subscribers={1 if args.record_images else 0}"]
    # Each run records into a folder of its own under --out (nothing there is replaced), and
    # its recording is deleted once measured (a flood run's holds the 4K frames).
    scratch = Path(tempfile.mkdtemp(prefix="recordings_", dir=args.out))
    frames = scenario.frame_count

    decode, decode_cpu_ms = decode_only(video, rig)
    stages = stage_times(video, rig)
    print(f"frames: {frames} of 3840x2160 (region {region[2]}x{region[3]} red)")
    print(f"decode-only: {decode:.1f} fps, {decode_cpu_ms:.1f} ms CPU per frame "
          f"({decode * decode_cpu_ms / 1e3:.2f} cores busy)")
    print("stages [ms/frame, mean]: " + ", ".join(f"{k} {v:.2f}" for k, v in stages.items()))
    reorder_s = reorder_delays_s(video, scenario.fps)
    print(f"{args.stream} stream: a frame waits for later packets (B-frames) "
          f"{1e3 * np.nanmedian(reorder_s):.1f} ms of media time (median; at most "
          f"{1e3 * np.nanmax(reorder_s):.1f}) before any decoder can give it out")
    camera_fps = decode / 2 if args.fps == "half-decode" else float(args.fps or scenario.fps)
    pace = [f"camera.rate={camera_fps / scenario.fps:.6f}",
            f"camera.low_delay={str(args.low_delay).lower()}"]
    print(f"real-time runs: the camera at {camera_fps:.1f} fps")
    for index, layout in enumerate([] if args.no_flood else args.layouts):
        processes = LAYOUTS[layout]
        recording = scratch / f"flood_{index}.mcap"
        receipts, _, _, memory, cpu, _ = run_graph(
            [*base, f"recorder.output={recording}",
             f"camera.max_in_flight={args.in_flight}", f"tracker.image_depth={args.in_flight}"],
            frames, None, processes=processes)
        recording.unlink(missing_ok=True)
        graph = (len(receipts) - 1) / (receipts[-1][0] - receipts[0][0])
        print(f"{layout}, flood ({args.in_flight} in flight, packets recorded): {graph:.1f} fps, "
              f"ratio {graph / decode:.2f}, {len(receipts)}/{frames} frames")
        print("  CPU per frame [ms]: " + ", ".join(f"{k} {v:.1f}" for k, v in cpu.items())
              + f"; total {sum(cpu.values()):.1f} (2 cores give {2e3 / graph:.1f})")
        peaks = {k.removesuffix(" peak"): v[-1][1] / 1024 for k, v in memory.items()
                 if k.endswith(" peak")}
        print("  peak memory [MB]: " + ", ".join(f"{k} {v:.0f}" for k, v in peaks.items()))

    hampel_ms = HAMPEL_DELAY_FRAMES / scenario.fps * 1e3
    hog_counts = args.hogs or ([0, 1] if args.busy else [0])
    for index, (layout, hogs) in enumerate([(layout, hogs) for layout in args.layouts
                                            for hogs in hog_counts]):
        processes = LAYOUTS[layout]
        recording = scratch / f"real_time_{index}.mcap"
        # A core's worth of someone else's work each: the graph shares what is left.
        loads = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
                 for _ in range(hogs)]
        try:
            receipts, live, spots_live, memory, cpu, origin_s = run_graph(
                [*base, *side, *pace, "camera.pacing=realtime", "camera.repeat=0",
                 f"recorder.output={recording}",
                 "recorder.exclude=[/tracker/spots_live,/recon/points_live"
                 + ("]" if args.record_images else ",/camera/image,/lateral/image]")],
                None, args.minutes, image_subscribers=2 if args.record_images else 1,
                processes=processes, log_file=args.out / f"real_time_{index}.log",
                graphs=("drop.yaml", "lateral.yaml") if args.lateral else ("drop.yaml",))
        finally:
            for load in loads:
                load.kill()
                load.wait()
        packets = recorded_packets(recording, args.out / f"real_time_{index}.log")
        images = recorded_frames(recording, scenario.fps) if args.record_images else None
        side_images = (recorded_frames(recording, side_fps, "/lateral/image")
                       if args.record_images and args.lateral else None)
        recording.unlink(missing_ok=True)
        layout = f"{layout}{f', beside {len(loads)} busy process(es)' if loads else ''}"
        # Receipt times and stamps [s] of each probe topic, for a look at the run over time.
        np.savez(args.out / f"real_time_{index}.npz", points=np.array(receipts),
                 points_live=np.array(live), spots_live=np.array(spots_live))
        if len(receipts) < 60:
            print(f"{layout}, real time: only {len(receipts)} clouds arrived")
            continue
        # From when each frame was played: at a rate below 1 its stamp runs ahead of that.
        rate = camera_fps / scenario.fps
        if not np.isfinite(origin_s):
            if rate != 1.0:
                print(f"{layout}, real time: the camera's origin never came, no latency")
                continue
            origin_s = 0.0   # at the video's own rate a stamp is when its frame was played
        latency = np.array([r - played_s(s, origin_s, rate) for r, s in receipts[30:]]) * 1e3
        median, p95 = np.median(latency), np.percentile(latency, 95)
        print(f"{layout}, real time {args.minutes:g} min: {len(receipts)} clouds, "
              f"{(len(receipts) - 1) / (receipts[-1][0] - receipts[0][0]):.2f} fps")
        print(f"  latency frame -> PointCloud2 [ms]: median {median:.1f}, p95 {p95:.1f} "
              f"(of which the Hampel window's {hampel_ms:.1f}); processing alone: "
              f"median {median - hampel_ms:.1f}, p95 {p95 - hampel_ms:.1f}")
        if live:
            stamps = {s for _, s in receipts[30:]}
            measured = [(r, s) for r, s in live if s in stamps]
            first = [r - played_s(s, origin_s, rate) for r, s in measured]
            live_ms = np.array(first) * 1e3
            print(f"  latency frame -> first PointCloud2 (points_live) [ms]: median "
                  f"{np.median(live_ms):.1f}, p95 {np.percentile(live_ms, 95):.1f}, max "
                  f"{live_ms.max():.1f}; {len(stamps) - len(first)} of {len(stamps)} frames "
                  "without a live cloud")
            slow = np.array([played_s(s, origin_s, rate) for r, s in measured
                             if r - played_s(s, origin_s, rate) > 0.05])
            start_s = played_s(receipts[30][1], origin_s, rate)
            minutes = np.bincount(((slow - start_s) // 60).astype(int),
                                  minlength=int(args.minutes))
            print("  live clouds later than 50 ms, per minute of the run: "
                  + " ".join(str(n) for n in minutes))
            # The stream's own wait comes before any decoding: what is left is the graph's.
            waits = [reorder_s[round((s - origin_s) * scenario.fps) % len(reorder_s)] / rate
                     for _, s in measured]
            graph_ms = live_ms - np.array(waits) * 1e3
            if np.isfinite(graph_ms).any():
                print(f"  of which after the stream's reordering (the graph's own) [ms]: "
                      f"median {np.nanmedian(graph_ms):.1f}, p95 "
                      f"{np.nanpercentile(graph_ms, 95):.1f}")
        if spots_live:
            stamps = {s for _, s in receipts[30:]}
            spots_ms = np.array([r - played_s(s, origin_s, rate) for r, s in spots_live
                                 if s in stamps]) * 1e3
            print(f"  of which frame -> live spots (camera and tracker) [ms]: median "
                  f"{np.median(spots_ms):.1f}, p95 {np.percentile(spots_ms, 95):.1f}")
        stamps = np.unique([s for _, s in receipts])
        camera_frames = round((stamps[-1] - stamps[0]) * scenario.fps) + 1
        print(f"  frames measured: {len(stamps)} of the camera's {camera_frames} in that time "
              f"({camera_frames - len(stamps)} skipped)")
        print(f"  packets recorded: {packets[0]} of the {packets[1]} the camera published "
              "(its line at the stop)")
        if images is not None:
            print(f"  frames recorded: {images[0]} of the camera's {images[1]} from the first "
                  "recorded to the last")
        if side_images is not None:
            print(f"  side frames recorded: {side_images[0]} of the side camera's "
                  f"{side_images[1]} from the first recorded to the last")
        said = [line.strip() for line in (args.out / f"real_time_{index}.log").read_text()
                .splitlines() if "shed" in line or "missing before" in line]
        print(f"  the console said, {len(said)} lines" + "".join(
            f"\n    {line}" for line in (said if len(said) <= 4 else said[:2] + said[-2:])))
        print("  CPU per frame [ms]: " + ", ".join(f"{k} {v:.1f}" for k, v in cpu.items()))
        for name, samples in memory.items():
            if name.endswith(" peak") or len(samples) < 4:
                continue
            t, rss = np.array(samples, dtype=float).T
            half = len(t) // 2
            slope = np.polyfit(t[half:] / 60, rss[half:] / 1024, 1)[0]
            print(f"  memory {name}: {rss[0] / 1024:.0f} -> {rss[-1] / 1024:.0f} MB RSS, "
                  f"second-half slope {slope:+.2f} MB/min")
    if args.check_process:
        check_process(args.out, scratch, video, rig_file, base, pace, hog_counts[-1])
    scratch.rmdir()


def check_process(out: Path, scratch: Path, video: Path, rig_file: Path, base: list[str],
                  pace: list[str], hogs: int) -> None:
    """One real-time play of the file beside `hogs` busy processes; `sds process --mcap` on
    its recording against `sds process --video` on the file, table by table."""
    recording = scratch / "check.mcap"
    loads = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(hogs)]
    try:
        run_graph([*base, *pace, "camera.pacing=realtime", f"recorder.output={recording}"],
                  None, None, image_subscribers=1, log_file=out / "check.log")
    finally:
        for load in loads:
            load.kill()
            load.wait()
    sds = str(Path(sys.executable).with_name("sds"))
    for flag, source, folder in (("--mcap", recording, scratch / "from_mcap"),
                                 ("--video", video, scratch / "from_video")):
        subprocess.run([sds, "process", flag, str(source), "--rig", str(rig_file), "--out",
                        str(folder), "--no-progress"], check=True, capture_output=True)
    shed = [line.strip() for line in (out / "check.log").read_text().splitlines()
            if "end of" in line]
    print(f"process --mcap against --video, one real-time play beside {hogs} busy "
          f"process(es): {shed[-1] if shed else 'no end line'}")
    for table in ("spots.csv", "points.csv", "line.csv", "fits.csv"):
        same = (scratch / "from_mcap" / table).read_bytes() == \
            (scratch / "from_video" / table).read_bytes()
        print(f"  {table}: {'identical' if same else 'DIFFERENT'}")
    for folder in ("from_mcap", "from_video"):
        shutil.rmtree(scratch / folder)
    recording.unlink()


if __name__ == "__main__":
    sys.exit(main())
