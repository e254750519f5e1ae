"""The reconstruction node as a real process: spots and line in, PointCloud2 and fits out."""

from __future__ import annotations

import time

import numpy as np
import psutil
import pytest
from ros_helpers import Probe, SdsGraphRun, wait_until
from sds_model.mode_theory import ModeShape
from sds_model.rig import load_rig
from sds_nodes.sloshing import SloshingNode
from sds_recon.reconstruction import LINE_LASER_ID
from sds_ros.point_cloud import cloud_dtype
from sds_ros.qos import stream_qos
from sds_sim.optics import line_laser_rays, ray_surface_points
from sds_sim.surface import ModeMotion, Surface
from sds_sloshing.running import RunningAnalysis
from sensor_msgs.msg import PointCloud2

from sds_msgs.msg import (
    LaserLineProfile,
    LaserSpot,
    LaserSpotArray,
    SloshingEstimate,
    SurfaceFit,
)

pytestmark = pytest.mark.ros

TILT_DEG = 12.0



def cloud_points(msg: PointCloud2) -> np.ndarray:
    assert msg.point_step == cloud_dtype().itemsize
    assert [f.name for f in msg.fields] == list(cloud_dtype().names)
    return np.frombuffer(bytes(msg.data), dtype=cloud_dtype())


def test_spots_and_line_in_point_cloud_and_fit_out(repo):
    rig_file = repo / "config" / "rigs" / "stelium.yaml"
    rig = load_rig(rig_file)
    surface = Surface(55.0, (), np.radians(TILT_DEG), 0.0, 2.0)
    emitters = np.array([d.emitter_mm for d in rig.diodes])
    directions = np.array([d.direction for d in rig.diodes])
    truth = ray_surface_points(surface, emitters, directions, 0.0)
    pixels = rig.project(truth)
    rays = line_laser_rays(rig.line_laser, 55.0, 300)
    line_truth = ray_surface_points(surface, np.repeat(rig.line_laser.emitter_mm[None], 300, 0),
                                    rays, 0.0)
    line_truth = line_truth[np.isfinite(line_truth).all(axis=1)]
    line_pixels = rig.project(line_truth)

    probe = Probe("recon_probe")
    graph = SdsGraphRun("recon.yaml", "--set", f"recon.rig={rig_file}")
    try:
        clouds = probe.collect(PointCloud2, "/recon/points", stream_qos())
        line_clouds = probe.collect(PointCloud2, "/recon/line_points", stream_qos())
        fits = probe.collect(SurfaceFit, "/recon/surface_fit", stream_qos())
        spots_pub = probe.node.create_publisher(LaserSpotArray, "/tracker/spots", stream_qos())
        line_pub = probe.node.create_publisher(LaserLineProfile, "/tracker/line", stream_qos())
        assert wait_until(lambda: spots_pub.get_subscription_count() > 0
                          and line_pub.get_subscription_count() > 0), graph.output()
        message = LaserSpotArray(frame_index=7)
        for diode, (x, y) in zip(rig.diodes, pixels, strict=True):
            spot = LaserSpot(laser_id=diode.laser_id, x_px=x, y_px=y, sigma_px=0.05)
            if diode.laser_id == 3:   # a lost spot gives no point
                spot.flags = LaserSpot.FLAG_LOST
                spot.x_px = spot.y_px = float("nan")
            message.spots.append(spot)
        spots_pub.publish(message)
        line_pub.publish(LaserLineProfile(frame_index=7, x_px=line_pixels[:, 0].tolist(),
                                          y_px=line_pixels[:, 1].tolist(),
                                          sigma_px=[0.1] * len(line_pixels),
                                          peak_intensity=[200.0] * len(line_pixels),
                                          flags=[0] * len(line_pixels)))
        assert wait_until(lambda: clouds and line_clouds and fits), graph.output()
        # frame 8: diode 5's blob is a reflection on its own image path, 3 mm high
        wrong = LaserSpotArray(frame_index=8, spots=list(message.spots))
        index = [d.laser_id for d in rig.diodes].index(5)
        hit = truth[index]
        beam = rig.diodes[index]
        along = (hit[2] + 3.0 - beam.emitter_mm[2]) / beam.direction[2]
        x, y = rig.project((beam.emitter_mm + along * beam.direction)[None])[0]
        wrong.spots[index] = LaserSpot(laser_id=5, x_px=x, y_px=y, sigma_px=0.05)
        spots_pub.publish(wrong)
        assert wait_until(lambda: len(clouds) > 1 and len(fits) > 1), graph.output()
    finally:
        probe.close()
        graph.stop()
    points = cloud_points(clouds[0])
    assert clouds[0].header.frame_id == "world"
    assert sorted(points["laser_id"]) == [d.laser_id for d in rig.diodes if d.laser_id != 3]
    expected = truth[[d.laser_id for d in rig.diodes].index(0)]
    row = points[points["laser_id"] == 0][0]
    # metres on the topic (REP-103), the truth in mm
    assert [row["x"], row["y"], row["z"]] == pytest.approx(expected / 1000, abs=1e-7)
    xyz = np.column_stack([points["x"], points["y"], points["z"]]) * 1000
    truth_by_id = {d.laser_id: t for d, t in zip(rig.diodes, truth, strict=True)}
    assert np.max(np.abs(xyz - np.array([truth_by_id[i] for i in points["laser_id"]]))) < 1e-4
    sigma_mm = points["height_sigma"] * 1000
    assert (sigma_mm > 0.005).all() and (sigma_mm < 0.1).all()
    assert np.max(points["miss_distance"]) < 1e-9
    line = cloud_points(line_clouds[0])
    assert (line["laser_id"] == LINE_LASER_ID).all() and len(line) == len(line_truth)
    line_xyz = np.column_stack([line["x"], line["y"], line["z"]]) * 1000
    assert np.max(np.abs(line_xyz - line_truth)) < 1e-4
    fit = fits[0]
    assert fit.frame_index == 7 and fit.point_count == 19
    assert np.degrees(fit.tilt_x_rad) == pytest.approx(TILT_DEG, abs=1e-6)
    assert fit.p00_mm == pytest.approx(2.0, abs=1e-6) and fit.rmse_mm < 1e-6
    assert "lateral_1_cos" in fit.mode_names
    assert fit.rejected_count == 0 and not points["rejected"].any()
    flagged = fits[1]
    assert flagged.rejected_count == 1 and list(flagged.rejected_laser_ids) == [5]
    assert flagged.point_count == 18
    assert np.degrees(flagged.tilt_x_rad) == pytest.approx(TILT_DEG, abs=1e-6)
    second = cloud_points(clouds[1])
    assert second["laser_id"][second["rejected"] == 1].tolist() == [5]


def test_missing_rig_is_a_clear_error():
    graph = SdsGraphRun("recon.yaml", "--set", "recon.rig=/nonexistent/rig.yaml")
    assert graph.wait(timeout=60) == 2
    assert "cannot load the rig" in graph.output() and "Traceback" not in graph.output()


def test_running_estimates_follow_a_decay(repo):
    """A 1 g lateral decay fed frame by frame: the node publishes its frequency and damping."""
    rig_file = repo / "config" / "rigs" / "stelium.yaml"
    rig = load_rig(rig_file)
    motion = ModeMotion(ModeShape(1, 1), 3.0, 2.79, 0.01, 0.0, 0.2)
    emitters = np.array([d.emitter_mm for d in rig.diodes])
    directions = np.array([d.direction for d in rig.diodes])
    probe = Probe("recon_probe")
    graph = SdsGraphRun("recon.yaml", "--set", f"recon.rig={rig_file}")
    try:
        every = stream_qos(200)   # all 120 fits
        estimates = probe.collect(SloshingEstimate, "/recon/sloshing", every)
        fits = probe.collect(SurfaceFit, "/recon/surface_fit", every)
        spots_pub = probe.node.create_publisher(LaserSpotArray, "/tracker/spots", stream_qos())
        # The sloshing node (its own process) subscribes to the fits besides this probe.
        assert wait_until(lambda: spots_pub.get_subscription_count() > 0
                          and probe.node.count_publishers("/recon/sloshing") > 0
                          and probe.node.count_subscribers("/recon/surface_fit") >= 2), \
            graph.output()
        for frame in range(120):
            time_s = frame / 30.0
            surface = Surface(55.0, (motion,))
            pixels = rig.project(ray_surface_points(surface, emitters, directions, time_s))
            message = LaserSpotArray(frame_index=frame)
            message.header.stamp.sec, nanosec = divmod(round(time_s * 1e9), 10**9)
            message.header.stamp.nanosec = nanosec
            message.spots = [LaserSpot(laser_id=d.laser_id, x_px=x, y_px=y, sigma_px=0.05)
                             for d, (x, y) in zip(rig.diodes, pixels, strict=True)]
            spots_pub.publish(message)
            time.sleep(0.005)
        assert wait_until(lambda: len(fits) == 120), graph.output()
        assert wait_until(lambda: any(e.window_end_s > 2.9 for e in estimates)), graph.output()
        niceness = {psutil.Process(pid).nice() for pid in graph.child_pids()}
        # The estimates' process runs 10 steps nicer than the reconstruction's (recon.yaml).
        assert len(niceness) == 2 and max(niceness) - min(niceness) == 10
    finally:
        probe.close()
        graph.stop()
    last = [e for e in estimates if e.window_end_s == max(x.window_end_s for x in estimates)]
    pencil = next(e for e in last if e.mode == "lateral_1" and e.method == "matrix_pencil")
    assert pencil.frequency_hz == pytest.approx(2.79, rel=1e-3)
    assert pencil.damping_ratio == pytest.approx(0.01, rel=0.05)
    assert 0.2 <= pencil.window_start_s <= 0.2 + 1 / 2.79 / 4 + 0.04   # the first crest


def test_fits_that_come_during_an_estimate_get_their_own(monkeypatch):
    """Fits that all arrive while an estimate runs (a loaded machine, a flooding replay) are
    estimated once it ends: the drop's last period is not left waiting for a fit."""
    slow = RunningAnalysis.estimate

    def slow_estimate(self, series):
        time.sleep(0.5)
        return slow(self, series)

    monkeypatch.setattr(RunningAnalysis, "estimate", slow_estimate)
    probe = Probe("sloshing_probe")
    node = SloshingNode("sloshing", context=probe.context)
    probe.executor.add_node(node)
    try:
        every = stream_qos(200)
        estimates = probe.collect(SloshingEstimate, "sloshing", every)
        fits_pub = probe.node.create_publisher(SurfaceFit, "surface_fit", every)
        assert wait_until(lambda: fits_pub.get_subscription_count() > 0)
        names = ["mean", "lateral_1_cos", "lateral_1_sin"]
        started = time.monotonic()
        for frame in range(91):   # 3 s of data in much less than the first estimate's 0.5 s
            time_s = frame / 30.0
            omega_t = 2 * np.pi * 2.79 * time_s
            wall = 3.0 * np.exp(-0.01 * omega_t) * np.cos(omega_t)
            fit = SurfaceFit(frame_index=frame, mode_names=names,
                             modal_amplitudes_mm=[0.0, wall, 0.0])
            fit.header.stamp.sec, fit.header.stamp.nanosec = divmod(round(time_s * 1e9), 10**9)
            fits_pub.publish(fit)
        assert time.monotonic() - started < 0.3
        assert wait_until(lambda: any(e.window_end_s > 2.9 for e in estimates), timeout=10)
    finally:
        probe.executor.remove_node(node)
        node.destroy_node()
        probe.close()
    pencil = next(e for e in estimates if e.mode == "lateral_1" and e.method == "matrix_pencil")
    assert pencil.frequency_hz == pytest.approx(2.79, rel=1e-3)


def test_under_a_rolling_shutter_each_point_has_its_time_and_every_frame_its_fit(repo, tmp_path):
    """The camera file says the rows are read over 20 ms: every cloud point carries its row's
    time after the stamp, a frame's cloud and fit come with the next frame's spots (its fit at
    the frame's time), and the last frame's once no spots came for a second."""
    from sds_ros.point_cloud import read_cloud
    from sds_sim.rolling_shutter import rolling_rig

    rig_file = rolling_rig(repo / "config" / "rigs" / "stelium.yaml", 0.02, tmp_path)
    rig = load_rig(rig_file)
    surface = Surface(55.0, (), np.radians(TILT_DEG), 0.0, 2.0)   # still: the same each time
    emitters = np.array([d.emitter_mm for d in rig.diodes])
    directions = np.array([d.direction for d in rig.diodes])
    pixels = rig.project(ray_surface_points(surface, emitters, directions, 0.0))
    probe = Probe("rolling_probe")
    graph = SdsGraphRun("recon.yaml", "--set", f"recon.rig={rig_file}")
    try:
        clouds = probe.collect(PointCloud2, "/recon/points", stream_qos())
        fits = probe.collect(SurfaceFit, "/recon/surface_fit", stream_qos())
        spots_pub = probe.node.create_publisher(LaserSpotArray, "/tracker/spots", stream_qos())
        assert wait_until(lambda: spots_pub.get_subscription_count() > 0), graph.output()
        for frame in range(3):
            message = LaserSpotArray(frame_index=frame)
            message.header.stamp.sec = 100 + frame
            message.spots = [LaserSpot(laser_id=d.laser_id, x_px=x, y_px=y, sigma_px=0.05)
                             for d, (x, y) in zip(rig.diodes, pixels, strict=True)]
            spots_pub.publish(message)
            if frame == 1:
                assert wait_until(lambda: len(fits) == 1), graph.output()
                time.sleep(0.3)
                assert len(fits) == 1 and fits[0].frame_index == 0   # frame 1 waits for 2
        assert wait_until(lambda: len(fits) == 3 and len(clouds) == 3, timeout=10), \
            graph.output()
    finally:
        probe.close()
        graph.stop()
    assert [f.frame_index for f in fits] == [0, 1, 2]
    assert all(np.degrees(f.tilt_x_rad) == pytest.approx(TILT_DEG, abs=1e-6) for f in fits)
    cloud = read_cloud(clouds[0])
    assert cloud is not None and cloud.sample_offsets_s is not None
    rows = {d.laser_id: y for d, (_, y) in zip(rig.diodes, pixels, strict=True)}
    expected = np.array([0.02 * rows[int(i)] / 2160 for i in cloud.points.laser_ids])
    np.testing.assert_allclose(cloud.sample_offsets_s, expected, rtol=1e-5)
