"""The measuring chain as real node processes, with a progress bar (`sds demo`, `sds run`).

The graph is config/graphs/drop.yaml (frame source → tracker → reconstruction, recorder) and
view.yaml (a live Rerun viewer) where there is a display, plus what the caller adds (arduino.yaml:
the serial bridge; lateral.yaml: the side camera).
`run_chain` starts it, counts the tracked frames, feeds a stand-in Arduino through a
pseudo-terminal when given its lines, and stops the graph once every frame is in.
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import time
import tty
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from sds_arduino.replay import paced
from sds_model.paths import CONFIG
from sds_ros.graph_file import NodeEntry, apply_overrides, load_graph
from tqdm import tqdm

from sds_bringup.launcher import Launcher
from sds_bringup.ros_env import graph_domain_id, graph_environment

if TYPE_CHECKING:   # rclpy is imported where a graph runs, not with the launcher
    from rclpy.node import Node

GRAPHS = ("drop.yaml", "view.yaml")
IDLE_TIMEOUT_S = 60.0
BRIDGE_OPEN_S = 0.5
"""The bridge opens its port within this of publishing (it reads from its start)."""
SIDE_ACK_TOPIC = "/lateral/frame_ack"
"""Where drop.yaml's recorder acknowledges each side frame it wrote (lateral.yaml)."""
RECORDER_NODE = "recorder"
"""drop.yaml's recorder node, whose subscriptions the stand-in Arduino waits for."""
ARDUINO_TOPICS = ("/arduino/imu", "/arduino/tof", "/arduino/events")
"""What arduino.yaml's bridge publishes from the serial stream."""


@dataclass(frozen=True)
class RunOutputs:
    """Where a run put its files, and how its graph ended."""

    recording: Path
    rerun: Path
    log: Path
    failure: str | None = None
    """The needed node that failed and why (None if none did)."""
    interrupted: bool = False
    """Whether Ctrl-C (or SIGTERM) stopped the graph."""


def live_view() -> bool:
    """Whether a live viewer can be shown (a display)."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def graph_entries(overrides: list[str], viewer: bool, extra: tuple[str, ...] = ()
                  ) -> list[NodeEntry]:
    """The chain: drop.yaml, with view.yaml if `viewer`, and the `extra` graph files (e.g.
    arduino.yaml, lateral.yaml), with overrides (the viewer's are left out without it)."""
    graphs = (*GRAPHS, *extra) if viewer else tuple(g for g in (*GRAPHS, *extra)
                                                    if g != "view.yaml")
    entries = [e for name in graphs for e in load_graph(CONFIG / "graphs" / name)]
    return apply_overrides(entries, [o for o in overrides
                                     if viewer or not o.startswith("viewer.")])


def run_chain(overrides: list[str], out: Path, expected_frames: int | None,
              serial_lines: list[bytes] | None = None, port: Path | None = None,
              graphs: tuple[str, ...] = (), side_frames: int | None = None) -> RunOutputs:
    """Run the chain (with the extra graph files `graphs`) until `expected_frames` fits were
    made and the recorder has acknowledged the `side_frames` of lateral.yaml's file if given
    (or Ctrl-C for a live camera), with a progress bar; node logs go to out/graph.log.
    The recorder refuses an existing recording unless the overrides say
    `recorder.overwrite=true`."""
    outputs = RunOutputs(out / "recording.mcap", out / "recording.rrd", out / "graph.log")
    domain_id = graph_domain_id(None)
    environment = graph_environment(domain_id)
    os.environ.update(environment)
    # The camera waits for the tracker on its frames and for the recorder on its packets
    # (drop.yaml); the tracker for reconstruction, recorder and
    # the progress bar; the reconstruction and the running sloshing estimates for the
    # recorder (the fits also for the sloshing node); each for the live viewer too if any.
    viewer = live_view()
    extra = int(viewer)
    entries = graph_entries([*overrides, f"recorder.output={outputs.recording.resolve()}",
                             "viewer.spawn=true", f"camera.wait_for_subscribers={1 + extra}",
                             f"tracker.wait_for_consumers={3 + extra}",
                             f"recon.wait_for_consumers={1 + extra}",
                             f"recon.wait_for_fit_consumers={2 + extra}",
                             f"sloshing.wait_for_consumers={1 + extra}",
                             *([f"lateral.wait_for_subscribers={1 + extra}"]
                               if "lateral.yaml" in graphs else [])], viewer, graphs)
    cable = plug_in(port) if serial_lines is not None and port is not None else None
    log = outputs.log.open("w")
    try:
        launcher = Launcher(entries, environment, output=log, console=sys.stderr)
        unplug, feeding = threading.Event(), threading.Event()
        watcher = threading.Thread(target=_watch, args=(
            launcher, expected_frames, side_frames, serial_lines, cable, unplug, feeding),
            daemon=True)
        print(f"running the graph on ROS_DOMAIN_ID={domain_id}: "
              + ", ".join(e.name for e in entries) + f" (log: {outputs.log})")
        try:
            launcher.run(on_started=watcher.start)
        finally:
            # The watcher's middleware threads must end before the interpreter does (else
            # the process aborts).
            launcher.request_stop()
            unplug.set()   # the stand-in Arduino leaves after the bridge
            if watcher.is_alive():
                watcher.join(timeout=5.0)
    finally:
        # A log on a full disk fails again on closing: the launcher has said so.
        with contextlib.suppress(OSError):
            log.close()
    if cable is not None and not feeding.is_set():
        for fd in cable:
            os.close(fd)
    if port is not None:
        port.unlink(missing_ok=True)   # the stand-in cable's link dangles once it is gone
    return replace(outputs, failure=launcher.failure,
                   interrupted=launcher.signal_received is not None)


def _watch(launcher: Launcher, expected_frames: int | None, side_frames: int | None,
           serial_lines: list[bytes] | None, cable: tuple[int, int] | None,
           unplug: threading.Event, feeding: threading.Event) -> None:
    """Count the tracked frames (progress bar) and the recorded side frames, feed the Arduino
    stream, stop the graph."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sds_ros.qos import stream_qos
    from std_msgs.msg import Header

    from sds_msgs.msg import LaserSpotArray

    context = rclpy.Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)
    node = Node("demo_progress", context=context)
    executor.add_node(node)
    tracked: list[int] = []   # frames tracked (the tracker waits for this subscriber too)
    node.create_subscription(LaserSpotArray, "/tracker/spots",
                             lambda msg: tracked.append(msg.frame_index), stream_qos(100))
    side_recorded: set[tuple[int, int]] = set()   # side frames the recorder acknowledged
    if side_frames:
        node.create_subscription(
            Header, SIDE_ACK_TOPIC, lambda msg: side_recorded.add((msg.stamp.sec,
                                                                   msg.stamp.nanosec)),
            QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    bar = tqdm(total=expected_frames, desc="frames", unit="frame")
    written = threading.Event()
    try:
        if cable is not None and serial_lines is not None:
            # The stand-in Arduino starts with the video, as on the rig: once the bridge has
            # opened the port (opening discards what waited in it) and the first frame is in.
            # And once the recorder takes the bridge's topics: it subscribes to a topic when
            # it sees it, which on a busy machine came 5 s after the bridge had published
            # all 470 records of a 2 s demo (none recorded, no imu.csv).
            while not launcher.stopping and not (_recording(node, ARDUINO_TOPICS)
                                                 and tracked):
                executor.spin_once(timeout_sec=0.05)
            time.sleep(BRIDGE_OPEN_S)
            feeding.set()
            threading.Thread(target=feed_serial, args=(cable, serial_lines, written, unplug),
                             daemon=True).start()
        last, last_side, last_change = 0, 0, time.monotonic()
        while not launcher.stopping:
            executor.spin_once(timeout_sec=0.1)
            if len(tracked) != last:
                bar.update(len(tracked) - last)
                last, last_change = len(tracked), time.monotonic()
            if len(side_recorded) != last_side:
                last_side, last_change = len(side_recorded), time.monotonic()
            done = expected_frames is not None and last >= expected_frames and \
                last_side >= (side_frames or 0) and (not feeding.is_set() or written.is_set())
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


def _recording(node: Node, topics: tuple[str, ...]) -> bool:
    """Whether the recorder has subscribed to every one of `topics`."""
    return all(any(info.node_name == RECORDER_NODE
                   for info in node.get_subscriptions_info_by_topic(topic))
               for topic in topics)


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
