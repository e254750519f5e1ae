"""The rolling shutter: its row times as the camera file states them, and `sds camera readout`
measuring a readout from a rendered flicker clip (the simulator's truth, H.264)."""

from __future__ import annotations

import csv
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from sds_camera.readout import video_readout
from sds_model.camera.model import CameraModelError
from sds_model.camera.rolling_shutter import RollingShutter, rolling_shutter
from sds_model.rig import load_rig
from sds_recon.reconstruction import SurfacePoints, fit_surface
from sds_recon.results import ResultsWriter, load_results
from sds_recon.surface_fit import ModalFit, modal_heights
from sds_sim.flicker import Flicker, flicker_clip
from sds_sim.rolling_shutter import rolling_rig, rolling_scenario
from sds_sim.scenario import load_scenario
from sds_sim.simulate import simulate
from sds_workflows.pipeline import FramePipeline, video_frames
from sds_workflows.run_tables import RunTables

from sds_workflows import process_video

SDS = str(Path(sys.executable).with_name("sds"))
READOUT_S = 0.020
"""The rolling kick's readout [s]: rows read top to bottom over 20 ms."""


def test_a_row_is_exposed_its_share_of_the_readout_after_the_first() -> None:
    shutter = RollingShutter(0.02)
    np.testing.assert_allclose(shutter.row_time_s([0.0, 540.0, 2159.0], 2160),
                               [0.0, 0.005, 0.02 * 2159 / 2160])
    upwards = RollingShutter(0.02, "bottom_to_top")
    np.testing.assert_allclose(upwards.row_time_s([2159.0, 0.0], 2160), [0.0, 0.02 * 2159 / 2160])
    assert rolling_shutter({}) == RollingShutter(0.0)          # absent: a global shutter
    assert rolling_shutter({"readout_s": 0.025, "readout_direction": "bottom_to_top"}) == \
        RollingShutter(0.025, "bottom_to_top")
    for content, message in (({"readout_s": -0.01}, "from 0"), ({"readout_s": "fast"}, "seconds"),
                             ({"readout_direction": "upwards"}, "one of")):
        with pytest.raises(CameraModelError, match=message):
            rolling_shutter(content)


@pytest.mark.parametrize("readout_s, flicker_hz, waveform, direction", [
    (0.020, 100.0, "sine", "top_to_bottom"),      # a lamp on 50 Hz mains
    (0.030, 110.0, "square", "bottom_to_top"),    # an LED's PWM
    (None, 100.0, "square", "top_to_bottom"),     # a random one
])
def test_sds_camera_readout_recovers_the_rendered_readout(
        readout_s: float | None, flicker_hz: float, waveform: str, direction: str,
        tmp_path: Path) -> None:
    rng = np.random.default_rng(int(flicker_hz) + len(waveform))
    readout_s = readout_s if readout_s is not None else float(rng.uniform(0.005, 0.032))
    exposure_s = float(rng.uniform(0.3e-3, 0.4 / flicker_hz))
    clip = flicker_clip(tmp_path / "flicker.mp4", 1280, 720, 30.0, 20,
                        RollingShutter(readout_s, direction),
                        Flicker(flicker_hz, 0.3, waveform), exposure_s, seed=7)
    done = subprocess.run([SDS, "camera", "readout", str(clip), "--flicker-hz",
                           str(flicker_hz)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    found = re.search(r"([\d.]+) ms ± ([\d.]+) ms", done.stdout)
    assert found, done.stdout
    measured_ms, sigma_ms = float(found.group(1)), float(found.group(2))
    assert abs(measured_ms - readout_s * 1e3) < 0.5, (measured_ms, readout_s)
    assert abs(measured_ms - readout_s * 1e3) < 4 * sigma_ms + 0.002, (measured_ms, sigma_ms)


def test_bands_that_stand_still_or_no_flicker_are_refused_in_one_line(tmp_path: Path) -> None:
    standing = flicker_clip(tmp_path / "standing.mp4", 640, 360, 30.0, 6, RollingShutter(0.02),
                            Flicker(120.0, 0.3), 1e-3)
    done = subprocess.run([SDS, "camera", "readout", str(standing), "--flicker-hz", "120"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "stand still" in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    steady = flicker_clip(tmp_path / "steady.mp4", 640, 360, 30.0, 6, RollingShutter(0.02),
                          Flicker(100.0, 0.0), 1e-3)
    with pytest.raises(ValueError, match="no flicker bands"):
        video_readout(steady, 100.0)


@pytest.fixture(scope="module")
def rolling_kick(repo: Path, tmp_path_factory) -> tuple:
    """A 1 g kick filmed by a camera whose rows are read top to bottom over 20 ms, its camera
    file saying so, processed by `process_video`: the scenario and the results."""
    folder = tmp_path_factory.mktemp("rolling")
    rig_file = rolling_rig(repo / "config" / "rigs" / "stelium.yaml", READOUT_S, folder)
    scenario = load_scenario(rolling_scenario(repo / "config" / "scenarios" / "ground_kick.yaml",
                                              rig_file, READOUT_S, folder), {"duration_s": 1.2})
    simulation = simulate(scenario, folder / "sim", progress=False)
    process_video(simulation.video, load_rig(rig_file), folder / "results",
                  progress=False)
    return scenario, simulation, load_results(folder / "results")



def true_heights(scenario, times_s, x_mm, y_mm) -> np.ndarray:
    """The simulator's surface at each (x, y) [mm] and time [s]."""
    return np.array([scenario.surface_at(t).height(x, y, t)
                     for t, x, y in zip(times_s, x_mm, y_mm, strict=True)])


def test_the_simulator_draws_each_spot_at_its_rows_time(rolling_kick) -> None:
    scenario, simulation, _ = rolling_kick
    with simulation.spots.open() as file:
        rows = [r for r in csv.DictReader(file) if r["visible"] == "1"]
    frame_s = np.array([float(r["time_s"]) for r in rows])
    sample_s = np.array([float(r["t_sample_s"]) for r in rows])
    row_px = np.array([float(r["y_px"]) for r in rows])
    np.testing.assert_allclose(sample_s - frame_s, READOUT_S * row_px / 2160, atol=1e-6)
    x, y, z = (np.array([float(r[k]) for r in rows]) for k in ("X_mm", "Y_mm", "Z_mm"))
    np.testing.assert_allclose(z, true_heights(scenario, sample_s, x, y), atol=1e-6)


def test_every_point_has_its_rows_time_and_is_the_surface_then(rolling_kick) -> None:
    """The points' heights against the true surface at their t_sample_s: as good as a global
    shutter's (0.05 mm on this kick); at the frame's time (what the results claimed before)
    they are several times worse."""
    scenario, _, results = rolling_kick
    points = results.points[(results.points["laser_id"] != 65535)
                            & (results.points["rejected"] == 0) & (results.points["t_s"] > 0.5)]
    x, y, z = points["X_mm"], points["Y_mm"], points["Z_mm"]
    at_sample = z - true_heights(scenario, points["t_sample_s"], x, y)
    at_frame = z - true_heights(scenario, points["t_s"], x, y)
    rmse_sample, rmse_frame = (float(np.sqrt(np.mean(e**2))) for e in (at_sample, at_frame))
    assert len(points) > 300 and rmse_sample <= 0.1, rmse_sample
    assert rmse_frame > 3 * rmse_sample, (rmse_frame, rmse_sample)
    assert "t_sample_s" in results.columns["points"]


def test_a_clouds_per_point_time_survives_the_message() -> None:
    from sds_ros.point_cloud import points_to_cloud, read_cloud
    from std_msgs.msg import Header

    points = SurfacePoints(np.array([1, 2]), np.array([[1.0, 2.0, 0.5], [3.0, 4.0, -0.5]]),
                           np.array([0.02, 0.03]), np.array([0.01, 0.02]), np.array([10.0, 2000.0]))
    offsets = RollingShutter(READOUT_S).row_time_s(points.row_px, 2160)
    timed = read_cloud(points_to_cloud(Header(), points, None, offsets))
    assert timed is not None and timed.sample_offsets_s is not None
    np.testing.assert_allclose(timed.sample_offsets_s, offsets, rtol=1e-6)
    untimed = points_to_cloud(Header(), points)
    assert "t" not in [f.name for f in untimed.fields]
    assert read_cloud(untimed).sample_offsets_s is None


def test_each_frames_fit_is_the_surface_at_the_frames_time(rolling_kick) -> None:
    """The modal fit of each frame against the true surface at the frame's time, at the
    diodes' places: within 0.1 mm; fitted on the points as measured (each at its row's time,
    what the fits were before) several times worse."""
    scenario, simulation, results = rolling_kick
    radius = scenario.rig.container.radius_mm
    names = tuple(n.removesuffix("_mm") for n in results.fits.dtype.names
                  if n.endswith("_mm") and n not in ("p00_mm", "rmse_mm"))
    with simulation.spots.open() as file:
        places: dict[int, list[tuple[float, float]]] = {}
        for row in csv.DictReader(file):
            places.setdefault(int(row["frame"]), []).append((float(row["X_mm"]),
                                                             float(row["Y_mm"])))
    at_frame_time, as_measured = [], []
    points = results.points[results.points["laser_id"] != 65535]
    for fit in results.fits[results.fits["t_s"] > 0.6]:
        frame, time_s = int(fit["frame"]), float(fit["t_s"])
        xy = np.array([p for p in places[frame] if np.isfinite(p).all()])
        true = scenario.surface_at(time_s).height(xy[:, 0], xy[:, 1], time_s)
        fitted = ModalFit(names, np.array([fit[f"{n}_mm"] for n in names]), 0.0, 0)
        at_frame_time += list(modal_heights(fitted, xy, radius) - true)
        measured = points[points["frame"] == frame]
        refit = fit_surface(SurfacePoints(
            measured["laser_id"], np.column_stack([measured["X_mm"], measured["Y_mm"],
                                                   measured["Z_mm"]]),
            measured["sigma_Z_mm"], measured["miss_mm"]), radius).modal
        as_measured += list(modal_heights(refit, xy, radius) - true)
    rmse, rmse_measured = (float(np.sqrt(np.mean(np.square(e))))
                           for e in (at_frame_time, as_measured))
    assert rmse <= 0.1 and rmse_measured > 3 * rmse, (rmse, rmse_measured)


def test_the_analysis_takes_each_frames_surface_at_the_frames_time(rolling_kick,
                                                                   tmp_path: Path) -> None:
    """What the analysis reads (per frame, each diode's point) is the surface at the frame's
    time: the points carried there, not as measured."""
    scenario, simulation, _ = rolling_kick
    rig = load_rig(scenario.rig_file)
    tables = RunTables(ResultsWriter(tmp_path), rig)
    for step in FramePipeline(rig).run(video_frames(simulation.video, rig)):
        tables.add_step(step)
    series = tables.surface_series("rolling kick")
    late = series.time_s > 0.6
    points = series.points_mm[late]            # frames × diodes × 3
    times = np.repeat(series.time_s[late][:, None], points.shape[1], axis=1)
    found = np.isfinite(points).all(axis=2)
    x, y, z = (points[..., axis][found] for axis in range(3))
    errors = z - true_heights(scenario, times[found], x, y)
    assert found.sum() > 300 and float(np.sqrt(np.mean(errors**2))) <= 0.1
    tables.writer.close()


def test_each_spot_message_carries_its_rows_time(repo: Path, tmp_path: Path) -> None:
    from sds_nodes.tracker import spots_msg
    from sds_tracker.tracker import TrackedSpot
    from std_msgs.msg import Header

    spots = [TrackedSpot(1, 100.0, 1080.0, 100.0, 1080.0, 0.05, 200.0, 0),
             TrackedSpot(2, np.nan, np.nan, np.nan, np.nan, 0.0, 0.0, 1)]   # lost
    rolling = load_rig(rolling_rig(repo / "config" / "rigs" / "stelium.yaml", READOUT_S,
                                   tmp_path))
    found, lost = spots_msg(Header(), 0, spots, rolling).spots
    assert found.t_offset_s == pytest.approx(READOUT_S * 1080 / 2160) and np.isnan(lost.t_offset_s)
    still = spots_msg(Header(), 0, spots, load_rig(repo / "config" / "rigs" / "stelium.yaml"))
    assert still.spots[0].t_offset_s == 0.0
