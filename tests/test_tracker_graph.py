"""A simulated drop through real processes: frame source -> tracker -> reconstruction, recorded;
then the recording replayed through tracker and reconstruction gives the same results."""

from __future__ import annotations

import csv
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap_ros2.reader import read_ros2_messages
from ros_helpers import Probe, SdsGraphRun
from rosbags.highlevel import AnyReader
from rrd_helpers import rrd_entities
from sds_recon.rig import load_rig
from sds_record.mcap_files import read_messages
from sds_sim.scenario import load_scenario
from sds_sim.simulate import simulate
from sensor_msgs.msg import Image, PointCloud2

from sds_msgs.msg import LaserLineProfile, LaserSpot, LaserSpotArray, SurfaceFit

pytestmark = pytest.mark.ros


def test_simulated_drop_is_tracked_and_reconstructed(repo, tmp_path):
    scenario = load_scenario(repo / "config" / "scenarios" / "ground_kick.yaml",
                             {"duration_s": 1.0})
    output = simulate(scenario, tmp_path / "sim", progress=False)
    rig_file = repo / "config" / "rigs" / "stelium.yaml"
    rig = load_rig(rig_file)
    region = list(rig.container_region_px(rig.camera))
    probe = Probe("drop_probe")
    spots = probe.collect(LaserSpotArray, "/tracker/spots")
    lines = probe.collect(LaserLineProfile, "/tracker/line")
    clouds = probe.collect(PointCloud2, "/recon/points")
    fits = probe.collect(SurfaceFit, "/recon/surface_fit")
    # The camera waits for three image subscribers: the tracker, the recorder and this probe
    # once it has found the tracker's and the reconstruction's publishers; the tracker takes
    # no frame before its spots reach three (the reconstruction, the recorder and this probe).
    recording = tmp_path / "drop.mcap"
    graph = SdsGraphRun("drop.yaml", "--set", f"camera.source={output.video}",
                        "--set", f"camera.roi={region}", "--set", f"tracker.rig={rig_file}",
                        "--set", f"recon.rig={rig_file}", "--set", "camera.wait_for_subscribers=3",
                        "--set", "tracker.wait_for_consumers=3",
                        "--set", f"recorder.output={recording}")
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not all(
                probe.node.count_publishers(topic) for topic in
                ("/tracker/spots", "/tracker/line", "/recon/points", "/recon/surface_fit")):
            time.sleep(0.1)
        time.sleep(0.5)
        probe.collect(Image, "/camera/image")
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and (len(spots) < 30 or len(fits) < 30):
            time.sleep(0.2)
        time.sleep(0.5)   # the recorder receives what the probe did
    finally:
        graph.stop()
        probe.close()
    assert sorted(m.frame_index for m in spots) == list(range(30)), graph.output()
    assert len(lines) == 30 and len(clouds) == 30 and len(fits) == 30
    with output.spots.open() as file:
        truth = {(int(r["frame"]), int(r["laser_id"])): r for r in csv.DictReader(file)}
    errors = []
    for message in spots:
        for spot in message.spots:
            row = truth[(message.frame_index, spot.laser_id)]
            if row["visible"] == "0":
                assert spot.flags & LaserSpot.FLAG_LOST
                continue
            assert not spot.flags & LaserSpot.FLAG_LOST
            errors.append([spot.x_px - float(row["x_exposure_px"]),
                           spot.y_px - float(row["y_exposure_px"])])
    errors = np.array(errors)
    # H.264 at the camera's quality costs accuracy against the lossless truth.
    assert np.sqrt(np.mean(errors**2)) < 0.15 and np.abs(errors).max() < 1.0
    heights = [f.p00_mm for f in fits]
    assert np.all(np.abs(heights) < 1.0)

    check_recording(recording, rig_file, tmp_path)


def topic_data(path) -> dict[str, list[bytes]]:
    """Every message's serialized content, per topic, in log-time order."""
    messages: dict[str, list[bytes]] = {}
    for message in read_messages(path):
        messages.setdefault(message.topic, []).append(message.data)
    return messages


def check_recording(recording, rig_file, tmp_path) -> None:
    """The drop's MCAP holds every message, reads in both readers, and replays identically."""
    recorded = topic_data(recording)
    assert {topic: len(data) for topic, data in recorded.items()
            if topic in ("/camera/image", "/camera/camera_model", "/tracker/spots",
                         "/recon/points", "/recon/surface_fit")} == {
        "/camera/image": 30, "/camera/camera_model": 1, "/tracker/spots": 30,
        "/recon/points": 30, "/recon/surface_fit": 30}
    decoded = [m.ros_msg.frame_index for m in read_ros2_messages(recording)
               if m.channel.topic == "/tracker/spots"]
    assert decoded == list(range(30))
    with AnyReader([recording]) as reader:
        connections = [c for c in reader.connections if c.topic == "/recon/surface_fit"]
        fits = [reader.deserialize(raw, c.msgtype)
                for c, _, raw in reader.messages(connections=connections)]
    assert [f.frame_index for f in fits] == list(range(30))

    replayed = tmp_path / "replay.mcap"
    graph = SdsGraphRun("replay.yaml", "--set", f"player.input={recording}",
                        "--set", f"tracker.rig={rig_file}", "--set", f"recon.rig={rig_file}",
                        "--set", f"recorder.output={replayed}")
    try:
        assert graph.wait(timeout=180) == 0, graph.output()
    finally:
        graph.stop()
    again = topic_data(replayed)
    for topic in ("/tracker/spots", "/tracker/line", "/recon/points", "/recon/line_points",
                  "/recon/surface_fit"):
        assert again[topic] == recorded[topic], topic

    view = subprocess.run([str(Path(sys.executable).with_name("sds")), "view", str(recording),
                           "--rig", str(rig_file), "--image-every", "10"],
                          capture_output=True, text=True, timeout=300)
    assert view.returncode == 0, view.stderr
    entities = rrd_entities(recording.with_suffix(".rrd"))
    for entity in ("/camera/image", "/camera/image/spots", "/camera/image/line",
                   "/world/points", "/world/line_points", "/world/fitted_plane"):
        assert entity in entities, sorted(entities)
