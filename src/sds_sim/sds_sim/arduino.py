"""The Arduino's records of a run: accelerometer, time of flight, trigger, LED, lasers."""

from __future__ import annotations

from functools import cache

import numpy as np
from sds_arduino.protocol import WRAP, Record

from sds_sim.scenario import Scenario

STANDARD_GRAVITY = 9.80665
ACCEL_RANGE_MG = 16000          # MPU6050 at ±16 g: the catapult's launch clips
CATAPULT_ACCELERATION_G = 30.0
CATAPULT_DURATION_S = 0.28
TOF_FOOTPRINT_SAMPLES = 400


def device_time_us(scenario: Scenario, time_s: np.ndarray) -> np.ndarray:
    """Arduino micros() at simulation times: offset and drift of its clock, wrapped at 2^32."""
    a = scenario.arduino
    ticks = np.round((np.asarray(time_s) + a.clock_offset_s) * (1 + a.clock_drift_ppm * 1e-6) * 1e6)
    return ticks.astype(np.int64) % WRAP


def specific_force_m_s2(scenario: Scenario, time_s: np.ndarray) -> np.ndarray:
    """What the accelerometer feels (N×3, m/s²): kick along x, gravity or free fall along z."""
    a, events = scenario.arduino, scenario.events
    t = np.asarray(time_s, dtype=float)
    force = np.zeros((len(t), 3))
    pulse = (t >= scenario.kick_s) & (t < scenario.kick_s + a.kick_duration_s)
    force[pulse, 0] = a.kick_peak_m_s2 * np.sin(np.pi * (t[pulse] - scenario.kick_s)
                                                / a.kick_duration_s)
    force[:, 2] = scenario.rig.gravity_m_s2
    if events.release_s is not None:
        force[t >= events.release_s, 2] = scenario.gravity
    if events.catapult_s is not None:
        launch = (t >= events.catapult_s) & (t < events.catapult_s + CATAPULT_DURATION_S)
        force[launch, 2] = CATAPULT_ACCELERATION_G * STANDARD_GRAVITY
    return force


@cache
def tof_footprint_mm(radius_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Fixed sample points (x, y) spread evenly over the half of the surface at x > 0."""
    rng = np.random.default_rng(0)
    r = radius_mm * np.sqrt(rng.uniform(0, 1, TOF_FOOTPRINT_SAMPLES))
    theta = rng.uniform(-np.pi / 2, np.pi / 2, TOF_FOOTPRINT_SAMPLES)
    return r * np.cos(theta), r * np.sin(theta)


def tof_range_mm(scenario: Scenario, time_s: float) -> float:
    """Distance from the ToF sensor to the liquid: its height minus the mean level it sees
    (the half of the surface at x > 0, as the seed's sensor covered about half)."""
    x, y = tof_footprint_mm(scenario.rig.container.radius_mm)
    level = scenario.surface_at(time_s).height(x, y, time_s)
    return scenario.arduino.tof_height_mm - float(np.mean(level))


def arduino_records(scenario: Scenario) -> list[Record]:
    """Every record of the run in device order, with sensor noise from the scenario's seed."""
    a, events = scenario.arduino, scenario.events
    rng = np.random.default_rng(scenario.seed + 1)
    entries: list[tuple[float, str, tuple[int, ...]]] = [(0.0, "LAS", (1,))]
    entries += [(events.trigger_s, "TRG", (1,)), (events.led_on_s, "LED", (1,)),
                (events.led_off_s, "LED", (0,))]
    imu_times = np.arange(0.0, scenario.duration_s, 1.0 / a.imu_rate_hz)
    force_mg = specific_force_m_s2(scenario, imu_times) / STANDARD_GRAVITY * 1000.0
    force_mg += rng.normal(0.0, a.accel_noise_mg, force_mg.shape)
    force_mg = np.clip(np.round(force_mg), -ACCEL_RANGE_MG, ACCEL_RANGE_MG).astype(int)
    entries += [(t, "IMU", tuple(int(v) for v in f)) for t, f in zip(imu_times, force_mg,
                                                                     strict=True)]
    for t in np.arange(0.0, scenario.duration_s, 1.0 / a.tof_rate_hz):
        measured = tof_range_mm(scenario, t) + rng.normal(0.0, a.tof_noise_mm)
        entries.append((t, "TOF", (round(measured), 0)))
    entries.sort(key=lambda entry: entry[0])
    times = device_time_us(scenario, np.array([e[0] for e in entries]))
    return [Record(seq, int(t_us), kind, values)
            for seq, ((_, kind, values), t_us) in enumerate(zip(entries, times, strict=True))]
