"""Simulation scenarios (config/scenarios/*.yaml): what the liquid does, and how it is seen."""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from sds_model.camera.model import CameraModelError
from sds_model.camera.rolling_shutter import rolling_shutter
from sds_model.errors import InputError
from sds_model.mode_theory import ModeShape, mode_root, natural_frequency_hz
from sds_model.rig import Rig, load_rig

from sds_sim.surface import ModeMotion, Surface


class ScenarioError(InputError):
    """A scenario file that cannot be simulated; the message names the bad field."""


@dataclass(frozen=True)
class ModeSpec:
    """One excited mode: order 1 lateral, 0 axisymmetric; frequency from theory unless given."""

    order: int
    index: int
    amplitude_mm: float
    damping_ratio: float
    azimuth_deg: float = 0.0
    phase_deg: float = 0.0
    frequency_hz: float | None = None


@dataclass(frozen=True)
class Optics:
    """How the lasers look: spot and line size on the liquid, brightness, speckle, exposure."""

    spot_diameter_mm: float = 1.5
    spot_peak: float = 420.0          # peak red level of a spot; above 255 it saturates
    line_width_mm: float = 0.8
    line_peak: float = 230.0
    speckle: float = 0.1              # speckle contrast (σ/mean of a spot's light) left after
                                      # the exposure averages the moving pattern: 0 none, 1
                                      # fully developed (exponential; a still's frozen one)
    speckle_grain_px: float = 0.7     # the grain's size (σ [px of the rendered image]): about
                                      # 1.22 λ N / pixel pitch, 1-3 px on a 4K GoPro image
    exposure_s: float = 1 / 60
    blur_samples: int = 5             # sub-exposure samples for motion blur
    line_rays: int = 600


@dataclass(frozen=True)
class Sensor:
    """Camera sensor effects: read noise (grey levels), shot noise, background level, the
    true camera's rolling shutter (`sds_model.camera.rolling_shutter`: each row exposed at its
    own time), and the bit rate its H.264 recording is written at."""

    read_noise: float = 2.0
    shot_noise: bool = True
    background: float = 18.0
    readout_s: float = 0.0            # rolling shutter: rows read over this time (0: global)
    readout_direction: str = "top_to_bottom"
    bitrate_mbit_s: float = 60.0      # H.264 at full resolution (a GoPro HERO5 at 4K, as stated)
    bloom_fraction: float = 0.0       # share of the light beyond saturation spread as a halo
    bloom_sigma_px: float = 4.0       # the halo's σ [px at full resolution]
    gain_step: float = 0.0            # auto exposure: per-frame σ of the gain's log random walk
    gain_range: tuple[float, float] = (0.7, 1.4)   # the gain stays within these
    ambient_gradient: float = 0.0     # ambient light: brightness change across the frame
                                      # (fraction, one direction drawn per run)
    vignetting: float = 0.0           # brightness lost at the frame's corners (fraction)


@dataclass(frozen=True)
class Disturbances:
    """What makes real footage hard: wall reflections, occlusions, vibration."""

    reflection_strength: float = 0.0         # relative to a spot; 0: no wall reflections
    occlusion_rate_per_s: float = 0.0        # short dropouts of single spots
    occlusion_frames: tuple[int, int] = (2, 5)
    glint_rate_per_s: float = 0.0            # one-frame glints anywhere on the liquid
    glint_peak: float = 300.0                # a glint's peak red level
    vibration_start_s: float | None = None   # catapult launch: the camera rings
    vibration_amplitude_deg: float = 0.05
    vibration_frequency_hz: float = 24.0
    vibration_decay_s: float = 0.25


@dataclass(frozen=True)
class Events:
    """Timeline [s]: trigger, LED sync blink, microgravity (gravity 0 from `release_s`)."""

    trigger_s: float = 0.2
    led_on_s: float = 0.3
    led_off_s: float = 0.5
    led_position_px: tuple[float, float] = (220.0, 220.0)   # in full-resolution pixels
    release_s: float | None = None                            # drop: free fall from here
    catapult_s: float | None = None                           # launch pulse start (catapult)


@dataclass(frozen=True)
class ArduinoSpec:
    """The Arduino's sensors: rates, noise, clock offset and drift, the lateral kick."""

    imu_rate_hz: float = 200.0
    tof_rate_hz: float = 33.0
    accel_noise_mg: float = 8.0
    tof_noise_mm: float = 0.8
    tof_height_mm: float = 165.0     # sensor above the flat surface
    clock_offset_s: float = 1.234
    clock_drift_ppm: float = 40.0
    kick_peak_m_s2: float = 4.0
    kick_duration_s: float = 0.06


@dataclass(frozen=True)
class CameraImuSpec:
    """The camera's own IMU (a GoPro's GPMF track): rates, noise, and its clock's offset."""

    enabled: bool = True
    accel_rate_hz: float = 200.0
    gyro_rate_hz: float = 400.0
    accel_noise_m_s2: float = 0.05
    gyro_noise_rad_s: float = 0.003
    offset_s: float = 0.0         # a sample stamped t was taken at video time t − offset_s
    start_s: float = -0.135       # first sample, on the video's clock (GoPro: before frame 0)


@dataclass(frozen=True)
class LateralSpec:
    """The side camera as built (seed Sec. 3: a second camera, 125 fps), against its view file
    (`sds_lateral.view`, what the user states): where it truly stands and looks, its clock,
    its intrinsics off the file, the checkerboard off its stated places, its image's levels."""

    view_file: str = "../lateral/stelium_side.yaml"   # relative to the scenario file
    position_mm: tuple[float, float, float] = (0.0, -400.0, -20.0)
    look_at_mm: tuple[float, float, float] = (0.0, 0.0, -5.0)
    roll_deg: float = 0.0
    clock_offset_s: float = -0.137    # its frame 0 on the top camera's clock [s]
    clock_drift_ppm: float = 15.0     # its clock runs fast by this much
    intrinsics_off_sigmas: float = 0.0   # each intrinsic off its file by this many of its σ
    board_offset_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)   # true − stated places
    background: float = 205.0         # the back-light seen through the empty container
    liquid: float = 28.0              # the opaque liquid behind the wall
    read_noise: float = 2.0
    psf_sigma_px: float = 0.7
    led_position_px: tuple[float, float] = (468.0, 44.0)


@dataclass(frozen=True)
class Scenario:
    """A reproducible simulated run."""

    name: str
    rig: Rig
    rig_file: Path
    seed: int = 0
    duration_s: float = 5.0
    fps: float = 30.0
    scale: float = 1.0                 # image scale (1: the camera file's size)
    gravity_m_s2: float | None = None  # None: the rig's gravity
    kick_s: float = 0.5                # lateral kick: modes start here
    modes: tuple[ModeSpec, ...] = ()
    tilt_deg: tuple[float, float] = (0.0, 0.0)
    tilt_series_deg: tuple[float, ...] = ()     # tilt table: one static tilt per segment
    tilt_series_axis: str = "x"
    offset_mm: float = 0.0
    meniscus_height_mm: float = 0.8
    optics: Optics = field(default_factory=Optics)
    sensor: Sensor = field(default_factory=Sensor)
    disturbances: Disturbances = field(default_factory=Disturbances)
    events: Events = field(default_factory=Events)
    arduino: ArduinoSpec = field(default_factory=ArduinoSpec)
    camera_imu: CameraImuSpec = field(default_factory=CameraImuSpec)
    lateral: LateralSpec | None = None   # None: no side camera

    @property
    def frame_count(self) -> int:
        """Frames in the run."""
        return round(self.duration_s * self.fps)

    @property
    def gravity(self) -> float:
        """Gravity of the liquid while it sloshes [m/s²]."""
        return self.rig.gravity_m_s2 if self.gravity_m_s2 is None else self.gravity_m_s2

    def mode_motions(self) -> tuple[ModeMotion, ...]:
        """Each excited mode with its frequency: given, or the 1 g theory with surface tension."""
        container, fluid = self.rig.container, self.rig.fluid
        motions = []
        for spec in self.modes:
            frequency = spec.frequency_hz
            if frequency is None:
                frequency = natural_frequency_hz(mode_root(spec.order, spec.index),
                                                 container.radius_mm, container.fill_height_mm,
                                                 self.gravity, fluid.surface_tension_n_m,
                                                 fluid.density_kg_m3)
            shape = ModeShape(spec.order, spec.index, np.radians(spec.azimuth_deg))
            motions.append(ModeMotion(shape, spec.amplitude_mm, frequency, spec.damping_ratio,
                                      np.radians(spec.phase_deg), self.kick_s))
        return tuple(motions)

    def tilt_at(self, time_s: float) -> tuple[float, float]:
        """Tilt table angles (x, y) [rad] at a time: fixed, or the series' current step.

        Step k holds from (k − ½)·T to (k + ½)·T (T = duration / steps; the first from the
        start, the last to the end), so a frame at k·T, e.g. one per step at fps = 1/T, sees
        one tilt over its whole exposure rather than a blend of two.
        """
        if not self.tilt_series_deg:
            return float(np.radians(self.tilt_deg[0])), float(np.radians(self.tilt_deg[1]))
        step = self.duration_s / len(self.tilt_series_deg)
        index = min(max(int(np.floor(time_s / step + 0.5)), 0), len(self.tilt_series_deg) - 1)
        angle = float(np.radians(self.tilt_series_deg[index]))
        return (angle, 0.0) if self.tilt_series_axis == "x" else (0.0, angle)

    def surface_at(self, time_s: float) -> Surface:
        """The surface model in force at `time_s`."""
        tilt_x, tilt_y = self.tilt_at(time_s)
        fluid, gravity = self.rig.fluid, max(self.gravity, 1e-6)
        capillary = 1e3 * np.sqrt(fluid.surface_tension_n_m / (fluid.density_kg_m3 * gravity))
        return Surface(self.rig.container.radius_mm, self.mode_motions(), tilt_x, tilt_y,
                       self.offset_mm, self.meniscus_height_mm,
                       float(np.clip(capillary, 0.5, self.rig.container.radius_mm / 4)))


def _build(cls: type, content: Any, where: str) -> Any:
    if content is None:
        return cls()
    if not isinstance(content, dict):
        raise ScenarioError(f"{where} must be a mapping")
    names = {f.name for f in fields(cls)}
    unknown = set(content) - names
    if unknown:
        raise ScenarioError(f"{where}: unknown keys {sorted(unknown)} (known: {sorted(names)})")
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in content.items()}
    try:
        return cls(**values)
    except TypeError as error:
        raise ScenarioError(f"{where}: {error}") from error


def load_scenario(path: str | Path, overrides: dict[str, Any] | None = None) -> Scenario:
    """Read a scenario file; `overrides` replace top-level keys (e.g. duration_s, scale)."""
    path = Path(path)
    try:
        content = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as error:
        raise ScenarioError(f"cannot read scenario {path}: {error}") from error
    if not isinstance(content, dict):
        raise ScenarioError(f"{path}: a scenario must be a mapping")
    content.update(overrides or {})
    if "rig" not in content:
        raise ScenarioError(f"{path}: rig is missing (a rig file, config/rigs/*.yaml)")
    rig_file = (path.parent / str(content.pop("rig"))).resolve()
    sections = {"optics": Optics, "sensor": Sensor, "disturbances": Disturbances,
                "events": Events, "arduino": ArduinoSpec, "camera_imu": CameraImuSpec}
    parts = {key: _build(cls, content.pop(key, None), key) for key, cls in sections.items()}
    lateral = content.pop("lateral", None)
    if lateral is not None:
        spec = _build(LateralSpec, lateral, "lateral")
        view_file = (path.parent / spec.view_file).resolve()
        if not view_file.is_file():   # before any frame is rendered
            raise ScenarioError(f"{path}: lateral.view_file {spec.view_file}: no such file "
                                f"({view_file}; a relative path is from the scenario's folder)")
        parts["lateral"] = replace(spec, view_file=str(view_file))
    modes = content.pop("modes", []) or []
    if not isinstance(modes, list):
        raise ScenarioError(f"{path}: modes must be a list")
    parts["modes"] = tuple(_build(ModeSpec, m, f"modes[{i}]") for i, m in enumerate(modes))
    for index, mode in enumerate(parts["modes"]):
        if not 0 <= mode.damping_ratio < 1 or mode.amplitude_mm < 0 or (
                mode.frequency_hz is not None and not mode.frequency_hz > 0):
            raise ScenarioError(
                f"{path}: modes[{index}]: damping_ratio {mode.damping_ratio:g} must be in [0, 1) "
                f"(a free decay), amplitude_mm {mode.amplitude_mm:g} not negative, "
                "frequency_hz positive")
    for key in ("tilt_deg", "tilt_series_deg"):
        if key in content:
            content[key] = tuple(float(v) for v in content[key])
    known = {f.name for f in fields(Scenario)} - {"rig", "rig_file"}
    unknown = set(content) - known
    if unknown:
        raise ScenarioError(f"{path}: unknown keys {sorted(unknown)}")
    scenario = Scenario(rig=load_rig(rig_file), rig_file=rig_file, **content, **parts)
    if scenario.duration_s <= 0 or scenario.fps <= 0 or not 0 < scenario.scale <= 1:
        raise ScenarioError(f"{path}: duration_s and fps must be > 0 and scale in (0, 1]")
    if scenario.tilt_series_axis not in ("x", "y"):
        raise ScenarioError(f"{path}: tilt_series_axis must be x or y")
    if not scenario.sensor.bitrate_mbit_s > 0:
        raise ScenarioError(f"{path}: sensor: bitrate_mbit_s {scenario.sensor.bitrate_mbit_s:g} "
                            "must be > 0 (the camera's H.264 rate, e.g. 60)")
    try:
        rolling_shutter({"readout_s": scenario.sensor.readout_s,
                         "readout_direction": scenario.sensor.readout_direction})
    except CameraModelError as error:
        raise ScenarioError(f"{path}: sensor: {error}") from None
    return scenario
