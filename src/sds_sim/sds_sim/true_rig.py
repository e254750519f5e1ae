"""True rigs that differ from their rig file: leaning beams, a moved camera, other layouts.

A rig file holds what the user believes (vertical beams, the camera where the drawing puts
it); the simulator renders the rig as it is. Tests give the pipeline the file and the frames
of the true rig, so nothing the pipeline assumes about the geometry is also used to make its
data (seed Sec. 3.3: the diodes lean "because of manufacturing errors"; Table 3's errors come
from the camera's assumed pose).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation
from sds_model.camera.model import CameraModel
from sds_model.geometry import RigidTransform
from sds_model.rig import LaserDiode, LineLaser, Rig


@dataclass(frozen=True)
class RigErrors:
    """How far the true rig departs from its file (all drawn at random, seeded)."""

    lean_sigma_deg: float = 0.6          # each beam's lean from its file direction (Rayleigh σ)
    lean_max_deg: float = 3.0            # leans are redrawn beyond this
    camera_angle_deg: float = 2.0        # camera rotation about each world axis, uniform ±
    camera_height_mm: float = 5.0        # camera centre along Z, uniform ±
    camera_lateral_mm: float = 1.0       # camera centre along X and Y, uniform ±
    emitter_sigma_mm: float = 0.0        # emitter position error, normal per axis
    line_normal_deg: float = 0.5         # the line laser's plane, rotated uniform ± per axis


def random_layout(rig: Rig, rng: np.random.Generator, count: int = 20,
                  radius_range_mm: tuple[float, float] = (12.0, 44.0),
                  height_range_mm: tuple[float, float] = (-15.0, 5.0),
                  min_spacing_mm: float = 10.0) -> Rig:
    """The rig with `count` diodes placed at random: radii, azimuths and emitter heights
    (relative to the camera centre, so not in the camera's plane), vertical beams, at least
    `min_spacing_mm` apart; the file a user would write for such a head."""
    camera_z = float(rig.camera_position_mm[2])
    emitters: list[np.ndarray] = []
    while len(emitters) < count:
        radius = np.sqrt(rng.uniform(radius_range_mm[0] ** 2, radius_range_mm[1] ** 2))
        azimuth = rng.uniform(0.0, 2 * np.pi)
        candidate = np.array([radius * np.cos(azimuth), radius * np.sin(azimuth),
                              camera_z + rng.uniform(*height_range_mm)])
        if all(np.hypot(*(candidate - e)[:2]) >= min_spacing_mm for e in emitters):
            emitters.append(candidate)
    radii = np.array([np.hypot(e[0], e[1]) for e in emitters])
    rings = np.digitize(radii, np.quantile(radii, [1 / 3, 2 / 3]))
    diodes = tuple(LaserDiode(k, int(3 - rings[k]), np.round(e, 3), np.array([0.0, 0.0, -1.0]))
                   for k, e in enumerate(emitters))
    return replace(rig, diodes=diodes)


def _lean(direction: np.ndarray, errors: RigErrors, rng: np.random.Generator) -> np.ndarray:
    """The direction tilted by a random lean (Rayleigh, σ per axis) towards a random azimuth."""
    while True:
        lean = np.radians(errors.lean_sigma_deg) * np.sqrt(-2 * np.log(1 - rng.uniform()))
        if lean <= np.radians(errors.lean_max_deg):
            break
    axis = np.cross(direction, rng.normal(size=3))
    axis /= np.linalg.norm(axis)
    return Rotation.from_rotvec(lean * axis).apply(direction)


def true_rig(rig: Rig, errors: RigErrors, rng: np.random.Generator) -> Rig:
    """The rig as built: every beam leaning, the camera turned and moved, emitters displaced."""
    diodes = tuple(LaserDiode(d.laser_id, d.ring,
                              d.emitter_mm + rng.normal(0.0, errors.emitter_sigma_mm, 3),
                              _lean(d.direction, errors, rng)) for d in rig.diodes)
    turn = Rotation.from_euler("xyz", rng.uniform(-1, 1, 3) * errors.camera_angle_deg,
                               degrees=True).as_matrix()
    shift = np.array([*rng.uniform(-1, 1, 2) * errors.camera_lateral_mm,
                      rng.uniform(-1, 1) * errors.camera_height_mm])
    camera_to_world = turn @ rig.world_to_camera.rotation.T
    position = rig.camera_position_mm + shift
    pose = RigidTransform(camera_to_world.T, -camera_to_world.T @ position)
    line = rig.line_laser
    if line is not None:
        tilt = Rotation.from_euler("xyz", rng.uniform(-1, 1, 3) * errors.line_normal_deg,
                                   degrees=True)
        line = LineLaser(line.emitter_mm.copy(), tilt.apply(line.normal))
    return replace(rig, diodes=diodes, world_to_camera=pose, line_laser=line)


def camera_as_calibrated(camera: CameraModel, sigma: dict[str, float], sigmas: float,
                         rng: np.random.Generator) -> CameraModel:
    """The true camera when a calibration with one-sigma errors `sigma` (a camera file's
    `sigma:`) gave `camera`: each of those intrinsics drawn off by `sigmas` × its σ (normal)."""
    return camera.with_intrinsics({name: sigmas * value * rng.normal()
                                   for name, value in sorted(sigma.items())})
