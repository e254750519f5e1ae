"""The simulator against analytic geometry, independent modal formulas and its own files."""

from __future__ import annotations

import csv
import hashlib
import itertools
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.special import jnp_zeros, jv
from sds_arduino.protocol import ProtocolError, Record, format_record, parse_line
from sds_camera.frame_source import VideoFileSource
from sds_model.mode_theory import ModeShape
from sds_model.rig import load_rig
from sds_sim.optics import ray_surface_points
from sds_sim.render import FrameRenderer
from sds_sim.scenario import ScenarioError, load_scenario
from sds_sim.simulate import simulate
from sds_sim.surface import ModeMotion, Surface

SDS = str(Path(sys.executable).with_name("sds"))


@pytest.fixture(scope="module")
def config(repo: Path) -> Path:
    return repo / "config"


def sloshing_surface() -> Surface:
    return Surface(55.0, (ModeMotion(ModeShape(1, 1, 0.3), 4.0, 2.79, 0.01),
                          ModeMotion(ModeShape(1, 2, 1.0), 1.0, 4.97, 0.02, 0.5),
                          ModeMotion(ModeShape(0, 1), 0.5, 4.19, 0.02)),
                   tilt_x_rad=0.05, meniscus_height_mm=1.0, meniscus_length_mm=1.7)


def test_beam_hits_lie_on_the_surface_and_on_the_beam() -> None:
    surface = sloshing_surface()
    rng = np.random.default_rng(0)
    origins = np.column_stack([rng.uniform(-45, 45, (200, 2)), np.full(200, 170.0)])
    directions = rng.normal([0, 0, -1], [0.05, 0.05, 0], (200, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    points = ray_surface_points(surface, origins, directions, time_s=0.37)
    inside = np.isfinite(points).all(axis=1)
    assert inside.sum() > 150
    p = points[inside]
    assert np.max(np.abs(p[:, 2] - surface.height(p[:, 0], p[:, 1], 0.37))) < 1e-9
    along = p - origins[inside]
    assert np.max(np.linalg.norm(np.cross(along, directions[inside]), axis=1)) < 1e-9
    reach = 170 / -directions[~inside, 2:]
    outside = np.hypot(*(origins[~inside, :2] + directions[~inside, :2] * reach).T)
    assert (outside > 50).all()  # the misses are beams that leave the container


def test_a_slanted_ray_finds_the_first_crossing() -> None:
    # A steep standing wave and a ray at 60 deg from vertical: sampled everywhere, the first
    # sign change along the ray is the only physical hit.
    surface = Surface(55.0, (ModeMotion(ModeShape(1, 3), 6.0, 6.2, 0.0, np.pi / 2),))
    origin = np.array([[-50.0, 0.0, 40.0]])
    direction = np.array([[np.sin(np.radians(60)), 0.0, -np.cos(np.radians(60))]])
    point = ray_surface_points(surface, origin, direction, 0.0)[0]
    s = np.linspace(0, np.linalg.norm(point - origin[0]), 20001)[:-1]
    along = origin + s[:, None] * direction
    assert (along[:, 2] > surface.height(along[:, 0], along[:, 1], 0.0)).all()


def test_flat_surface_height_comes_back_through_exact_triangulation(config: Path) -> None:
    scenario = load_scenario(config / "scenarios" / "ground_kick.yaml",
                             {"modes": [], "offset_mm": 3.7, "meniscus_height_mm": 0.0,
                              "scale": 0.25, "duration_s": 0.1})
    renderer = FrameRenderer(scenario)
    _, truth = renderer.render(0)
    rig = scenario.rig
    # Full-resolution pixels of the truth → camera rays → closest points to the beams.
    full_px = (truth.spot_px + 0.5) / scenario.scale - 0.5
    rays = rig.pixel_rays(full_px)
    centre = rig.camera_position_mm
    heights = []
    for ray, diode in zip(rays, rig.diodes, strict=True):
        w0 = centre - diode.emitter_mm
        a, b, c = ray @ ray, ray @ diode.direction, diode.direction @ diode.direction
        d, e = ray @ w0, diode.direction @ w0
        s = (b * e - c * d) / (a * c - b * b)
        t = (a * e - b * d) / (a * c - b * b)
        heights.append(((centre + s * ray) + (diode.emitter_mm + t * diode.direction))[2] / 2)
    assert np.max(np.abs(np.array(heights) - 3.7)) < 1e-6


def test_noiseless_spot_and_line_centroids_match_the_truth(config: Path) -> None:
    scenario = load_scenario(config / "scenarios" / "ground_kick.yaml", {
        "scale": 0.5, "duration_s": 2.0, "meniscus_height_mm": 0.0,
        "sensor": {"read_noise": 0.0, "shot_noise": False},
        "optics": {"speckle": 0.0, "spot_peak": 200.0, "line_peak": 200.0},
        "disturbances": {"reflection_strength": 0.0}})
    renderer = FrameRenderer(scenario)
    background = renderer.background[..., 2].astype(float)
    errors, line_errors = [], []
    for index in (20, 33, 47):   # the surface moving: motion blur over the exposure
        frame, truth = renderer.render(index)
        signal = frame[..., 2].astype(float) - background
        for x, y in truth.spot_exposure_px[truth.visible]:
            x0, y0 = round(x) - 9, round(y) - 9
            window = signal[y0:y0 + 19, x0:x0 + 19]
            ys, xs = np.mgrid[y0:y0 + 19, x0:x0 + 19]
            errors.append([np.sum(window * xs) / window.sum() - x,
                           np.sum(window * ys) / window.sum() - y])
        _, static = FrameRenderer(scenario).render(0)  # before the kick: a still line
        line_frame, _ = renderer.render(0)
        line_signal = line_frame[..., 2].astype(float) - background
        spots = static.spot_px[static.visible]
        for row, x in zip(static.line_rows[10:-10], static.line_x_px[10:-10], strict=True):
            if np.min(np.abs(spots[:, 1] - row)) < 12:
                continue  # a diode's spot on the same row
            x0 = round(x) - 8
            profile = line_signal[row, x0:x0 + 17]
            line_errors.append(np.sum(profile * np.arange(x0, x0 + 17)) / profile.sum() - x)
    errors = np.array(errors)
    assert len(errors) >= 50 and np.max(np.abs(errors)) < 0.02
    assert len(line_errors) > 300 and np.max(np.abs(line_errors)) < 0.02


def test_sloshing_truth_follows_the_modal_formulas(config: Path, tmp_path: Path) -> None:
    scenario = load_scenario(config / "scenarios" / "ground_kick.yaml",
                             {"scale": 0.25, "duration_s": 1.5, "meniscus_height_mm": 0.0})
    rig = scenario.rig
    radius, depth = rig.container.radius_mm * 1e-3, rig.container.fill_height_mm * 1e-3
    sigma, rho, g = rig.fluid.surface_tension_n_m, rig.fluid.density_kg_m3, rig.gravity_m_s2
    motions = scenario.mode_motions()
    for spec, motion in zip(scenario.modes, motions, strict=True):
        xi = jnp_zeros(spec.order, spec.index)[-1]
        stiffness = g * xi / radius + sigma * xi**3 / (rho * radius**3)
        omega2 = stiffness * np.tanh(xi * depth / radius)
        assert motion.frequency_hz == pytest.approx(np.sqrt(omega2) / (2 * np.pi), rel=1e-12)
    # The diodes' true heights: Σ q_k(t) J_m(ξ r/R)/J_m(ξ) cos(m θ), written out independently.
    renderer = FrameRenderer(scenario)
    for index in (16, 25, 40):
        _, truth = renderer.render(index)
        t = truth.time_s
        x, y = truth.spot_mm[:, 0], truth.spot_mm[:, 1]
        r, theta = np.hypot(x, y), np.arctan2(y, x)
        expected = np.zeros_like(r)
        for spec, motion in zip(scenario.modes, motions, strict=True):
            xi = jnp_zeros(spec.order, spec.index)[-1]
            omega = 2 * np.pi * motion.frequency_hz
            tau = t - scenario.kick_s
            q = spec.amplitude_mm * np.exp(-spec.damping_ratio * omega * tau) * np.sin(
                omega * np.sqrt(1 - spec.damping_ratio**2) * tau + np.radians(spec.phase_deg))
            expected += q * jv(spec.order, xi * r / rig.container.radius_mm) / jv(spec.order, xi) \
                * np.cos(spec.order * (theta - np.radians(spec.azimuth_deg)))
        assert np.max(np.abs(truth.spot_mm[:, 2] - expected)) < 1e-9


def test_protocol_round_trip_and_corruption() -> None:
    record = Record(41, 4_000_000_123, "IMU", (-12, 3, 998))
    line = format_record(record)
    assert line.endswith("\r\n") and parse_line(line) == record
    assert parse_line(line.encode()) == record
    for bad in (line.replace("998", "999"), line[:-6], "garbage\r\n", line.replace("IMU", "XYZ"),
                "$SDS2" + line[5:]):
        with pytest.raises(ProtocolError):
            parse_line(bad)
    with pytest.raises(ProtocolError):
        Record(1, 2, "TOF", (1,))


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open() as file:
        return list(csv.DictReader(file))


def test_sds_simulate_writes_video_streams_and_truth(config: Path, tmp_path: Path) -> None:
    scenario = config / "scenarios" / "ground_kick.yaml"
    args = [SDS, "simulate", str(scenario), "--seconds", "1.0", "--scale", "0.25",
            "--codec", "lossless"]
    result = subprocess.run([*args, "--out", str(tmp_path / "a")], capture_output=True,
                            text=True, timeout=300, check=False)
    assert result.returncode == 0, result.stderr
    run = json.loads((tmp_path / "a" / "truth" / "run.json").read_text())
    assert run["frame_count"] == 30 and run["image_size"] == [960, 540]
    source = VideoFileSource(tmp_path / "a" / "video.mp4")
    assert source.announced_frames == 30 and (source.width, source.height) == (960, 540)
    spots = read_csv(tmp_path / "a" / "truth" / "spots.csv")
    assert len(spots) == 30 * 20
    frames = read_csv(tmp_path / "a" / "truth" / "frames.csv")
    assert [int(f["led_on"]) for f in frames] == [int(0.3 <= i / 30 < 0.5) for i in range(30)]
    line = np.load(tmp_path / "a" / "truth" / "line.npz")
    assert line["line_x_px"].shape == (30, 540) and np.isfinite(line["line_x_px"]).sum() > 30 * 250
    # The LED blink is in the pixels where run.json says it is, in the frames it says.
    x, y = (int(v * run["image_scale"]) for v in run["events"]["led_position_px"])
    capture = cv2.VideoCapture(str(tmp_path / "a" / "video.mp4"))
    levels = [int(capture.read()[1][y, x].min()) for _ in range(30)]
    assert [level > 200 for level in levels] == [bool(int(f["led_on"])) for f in frames]
    # Arduino streams: valid records, contiguous sequence, device clock monotone.
    records = [parse_line(line) for line in
               (tmp_path / "a" / "arduino" / "serial.txt").read_text().splitlines()]
    assert [r.seq for r in records] == list(range(len(records)))
    assert all(b.t_us >= a.t_us for a, b in itertools.pairwise(records))
    imu = np.array([r.values for r in records if r.kind == "IMU"])
    assert np.mean(imu[:, 2]) == pytest.approx(1000.3, abs=15)   # 9.81 m/s² in mg
    kick = [r for r in records if r.kind == "IMU" and r.values[0] > 300]
    assert kick, "the lateral kick shows on the accelerometer"
    assert (tmp_path / "a" / "arduino" / "SDS_LOG.TXT").read_text() == \
        (tmp_path / "a" / "arduino" / "serial.txt").read_text()
    # Reproducible from the seed.
    again = subprocess.run([*args, "--out", str(tmp_path / "b")], capture_output=True, text=True,
                           timeout=300, check=False)
    assert again.returncode == 0
    for name in ("truth/spots.csv", "truth/frames.csv", "arduino/serial.txt"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()


@pytest.mark.parametrize("name, frames", [("ground_kick", 180), ("tilt_table", 240),
                                          ("drop_4p7s", 141), ("drop_9p3s_catapult", 279)])
def test_shipped_scenarios_load(config: Path, name: str, frames: int) -> None:
    scenario = load_scenario(config / "scenarios" / f"{name}.yaml")
    assert scenario.frame_count == frames and len(scenario.rig.diodes) == 20


def test_tilt_table_truth_is_the_tilted_plane(config: Path) -> None:
    scenario = load_scenario(config / "scenarios" / "tilt_table.yaml", {"scale": 0.25})
    renderer = FrameRenderer(scenario)
    for index, angle in ((0, 0.0), (35, 5.0), (235, 35.0)):
        _, truth = renderer.render(index)
        x = truth.spot_mm[:, 0]
        assert np.allclose(truth.spot_mm[:, 2], -x * np.tan(np.radians(angle)), atol=1e-9)


def test_the_video_is_written_at_the_cameras_bit_rate(config: Path, tmp_path: Path) -> None:
    """H.264 as the camera records it: the scenario's rate at full resolution, the same bits
    per pixel at a smaller scale (a rate far below the camera's shrinks sub-pixel motion)."""
    scale = 0.25
    for rate_mbit_s in (60.0, 20.0):
        scenario = load_scenario(config / "scenarios" / "ground_kick.yaml", {
            "duration_s": 1.0, "scale": scale, "sensor": {"bitrate_mbit_s": rate_mbit_s}})
        video = simulate(scenario, tmp_path / f"{rate_mbit_s:g}", progress=False).video
        written_mbit_s = video.stat().st_size * 8 / scenario.duration_s / 1e6
        assert written_mbit_s == pytest.approx(rate_mbit_s * scale**2, rel=0.3)


@pytest.mark.parametrize("change, message", [
    ({"modes": [{"order": 1, "index": 1, "amplitude": 2}]}, "unknown keys"),
    ({"optics": {"spot_size": 2}}, "optics: unknown keys"),
    ({"scale": 2.0}, "scale in"),
    ({"tilt_series_axis": "z"}, "tilt_series_axis"),
    ({"sensor": {"bitrate_mbit_s": 0}}, "sensor: bitrate_mbit_s 0 must be > 0"),
])
def test_bad_scenarios_are_refused_with_the_field(config: Path, change: dict, message: str) -> None:
    with pytest.raises(ScenarioError, match=message):
        load_scenario(config / "scenarios" / "ground_kick.yaml", change)


def test_rig_file_errors_name_the_field(config: Path, tmp_path: Path) -> None:
    text = (config / "rigs" / "stelium.yaml").read_text()
    (tmp_path / "cameras").mkdir()
    (tmp_path / "cameras" / "gopro_hero5_session.yaml").write_text(
        (config / "cameras" / "gopro_hero5_session.yaml").read_text())
    (tmp_path / "rigs").mkdir()
    broken = tmp_path / "rigs" / "rig.yaml"
    broken.write_text(text.replace("radius_mm: 55.0", "radius_mm: -55.0"))
    with pytest.raises(ValueError, match=r"container\.radius_mm must be positive"):
        load_rig(broken)
    broken.write_text(text.replace("direction: [0.0, 0.0, -1.0]}", "direction: [0, 0, 0]}", 1))
    with pytest.raises(ValueError, match=r"diodes\[0\].direction must not be zero"):
        load_rig(broken)


def test_a_scenario_gives_the_same_video_every_time(config: Path, tmp_path: Path) -> None:
    """Three runs of one scenario write byte-identical videos, so a run that went wrong can be
    made again (x264's frame threads under a bit-rate limit differed nearly every run)."""
    scenario = load_scenario(config / "scenarios" / "drop_4p7s.yaml",
                             {"duration_s": 1.0, "scale": 0.5})
    videos = {hashlib.sha256(simulate(scenario, tmp_path / str(run), progress=False)
                             .video.read_bytes()).hexdigest() for run in range(3)}
    assert len(videos) == 1, videos
