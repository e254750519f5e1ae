"""A simulated drop through real processes: frame source -> tracker -> reconstruction."""

from __future__ import annotations

import csv
import time

import numpy as np
import pytest
from ros_helpers import Probe, SdsGraphRun
from sds_recon.rig import load_rig
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
    # The camera waits for two image subscribers: the tracker, and this probe once it has
    # found the tracker's and the reconstruction's publishers; the tracker takes no frame
    # before its spots reach two subscribers (the reconstruction and this probe).
    graph = SdsGraphRun("drop.yaml", "--set", f"camera.source={output.video}",
                        "--set", f"camera.roi={region}", "--set", f"tracker.rig={rig_file}",
                        "--set", f"recon.rig={rig_file}", "--set", "camera.wait_for_subscribers=2",
                        "--set", "tracker.wait_for_consumers=2")
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
