"""The camera's own IMU in a simulated run: what a GoPro's GPMF track would hold.

The camera sits on the rig, so its accelerometer feels the rig's specific force (the kick,
gravity, the release into free fall, the catapult: `sds_sim.arduino.specific_force_m_s2`)
turned into the camera's optical frame by its pose, launch vibration included; its gyroscope
sees the vibration's rate. Each stream has its own rate and noise, and the camera's IMU clock
may be offset from the video's (`CameraImuSpec.offset_s`).
"""

from __future__ import annotations

import numpy as np
from sds_camera.camera_imu import CameraImu

from sds_sim.arduino import specific_force_m_s2
from sds_sim.render import vibration_rad
from sds_sim.scenario import Scenario

RATE_STEP_S = 1e-4
"""Time step of the central difference that gives the vibration's angular rate [s]."""


def _rotation(scenario: Scenario, time_s: float) -> np.ndarray:
    """World → optical rotation at a time: the rig's camera pose turned by the vibration."""
    from sds_model.geometry import RigidTransform

    angles = vibration_rad(scenario.disturbances, time_s)
    shake = RigidTransform.from_rotation_vector([angles[0], angles[1], 0.0], np.zeros(3))
    return shake.rotation @ scenario.rig.world_to_camera.rotation


def camera_imu(scenario: Scenario) -> CameraImu | None:
    """The camera's accelerometer and gyroscope streams of the run (None when disabled)."""
    spec = scenario.camera_imu
    if not spec.enabled:
        return None
    rng = np.random.default_rng(scenario.seed + 2)
    accel_t = np.arange(spec.start_s, scenario.duration_s, 1.0 / spec.accel_rate_hz)
    gyro_t = np.arange(spec.start_s, scenario.duration_s, 1.0 / spec.gyro_rate_hz)
    taken = accel_t - spec.offset_s          # when each stamped sample was really taken
    world = specific_force_m_s2(scenario, taken)
    accel = np.array([_rotation(scenario, t) @ f for t, f in zip(taken, world, strict=True)])
    accel += rng.normal(0.0, spec.accel_noise_m_s2, accel.shape)
    d = scenario.disturbances
    gyro = np.array([np.append((vibration_rad(d, t + RATE_STEP_S) -
                                vibration_rad(d, t - RATE_STEP_S)) / (2 * RATE_STEP_S), 0.0)
                     for t in gyro_t - spec.offset_s])
    gyro += rng.normal(0.0, spec.gyro_noise_rad_s, gyro.shape)
    return CameraImu(accel_t, accel, gyro_t, gyro, f"simulated ({scenario.name})")
