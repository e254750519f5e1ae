"""The rig's calibratable geometry as one parameter vector, and its residuals.

Parameters (`parameters.py`: one table with their priors; each a small change from the rig
file's or the surfaces CSV's value): camera rotation about the world X, Y, Z axes [rad] and
centre shift [mm]; the camera's intrinsics its file gives a σ for (`sigma:`); per beam two
tilts of its direction [rad] and, where the emitter's position is uncertain (a tolerance, or
`fit_emitters`), two shifts of its emitter across the beam [mm] (along the beam an emitter
shift changes nothing); per known surface whose reading is uncertain, its two angles [rad]
and its fill level [mm]; with line observations, two tilts of the line laser's plane about a
point on it [rad] and its shift along its normal [mm].

Residuals: spots are predicted as the beam's hit on the frame's surface (Eq. 9 with Z = g(X, Y)
known), projected through the camera (Eq. 1 and the camera model); a line pixel's residual is
the shift along its image row [px] that puts its ray's hit on the surface into the plane; a
parameter with a declared tolerance adds value / σ_prior.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation
from sds_model.camera.model import CameraModel
from sds_model.geometry import RigidTransform, ray_plane_points
from sds_model.rig import LineLaser, Rig

from sds_recon.calibration.lasers import KnownSurface
from sds_recon.calibration.parameters import (
    BEAM_KIND,
    CAMERA_POSITION_KIND,
    CAMERA_ROTATION,
    CAMERA_ROTATION_KIND,
    CAMERA_SHIFT,
    CAMERA_Z_DETERMINED_BY,
    EMITTER_KIND,
    LINE_OFFSET_KIND,
    LINE_PLANE,
    LINE_PLANE_KIND,
    SURFACE_OFFSET_KIND,
    SURFACE_TILT_KIND,
    Parameter,
    ParameterTable,
    intrinsic_kind,
)


@dataclass(frozen=True)
class LineObservations:
    """Line pixels on known surfaces: frame index, pixel (N×2, x sub-pixel along the row),
    σ [px]."""

    frame: np.ndarray
    pixels: np.ndarray
    sigma_px: np.ndarray

    def subset(self, keep: np.ndarray) -> LineObservations:
        """The observations where `keep` is true."""
        return LineObservations(self.frame[keep], self.pixels[keep], self.sigma_px[keep])


def across_axes(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to `direction` and to each other: the axes a beam's (or
    the line plane's) two tilt parameters turn it along."""
    helper = np.array([0.0, 0.0, 1.0]) if abs(direction[2]) < 0.9 else np.array([1.0, 0, 0])
    first = np.cross(helper, direction)
    first /= np.linalg.norm(first)
    return first, np.cross(direction, first)


def _prior(value: float | None, in_degrees: bool = False) -> float:
    """A declared tolerance as a prior σ [rad or mm]; inf where none was declared."""
    if value is None:
        return np.inf
    return float(np.radians(value)) if in_degrees else float(value)


def _parameters(rig: Rig, laser_ids: list[int], surfaces: list[KnownSurface],
                fit_emitters: bool, line: bool) -> ParameterTable:
    """The table of every parameter of a fit of these diodes on these surfaces."""
    tolerances = rig.tolerances
    angle, shift = _prior(tolerances.camera_angle_deg, True), _prior(tolerances.camera_position_mm)
    table = [Parameter(n, CAMERA_ROTATION_KIND, angle) for n in CAMERA_ROTATION]
    table += [Parameter(n, CAMERA_POSITION_KIND, shift,
                        CAMERA_Z_DETERMINED_BY if n == "camera Z" else "")
              for n in CAMERA_SHIFT]
    lean = _prior(tolerances.beam_lean_deg, True)
    for laser_id in laser_ids:
        table += [Parameter(f"beam {laser_id} tilt {axis}", BEAM_KIND, lean) for axis in "ab"]
        emitter_sigma = rig.emitter_sigma_mm(laser_id)
        if fit_emitters or emitter_sigma > 0:
            prior = emitter_sigma if emitter_sigma > 0 else np.inf
            table += [Parameter(f"emitter {laser_id} {axis}", EMITTER_KIND, prior)
                      for axis in "ab"]
    for index, surface in enumerate(surfaces):
        table += [Parameter(f"surface {index} tilt {axis}", SURFACE_TILT_KIND, sigma)
                  for axis, sigma in zip("xy", (surface.tilt_x_sigma_rad,
                                                surface.tilt_y_sigma_rad), strict=True)
                  if sigma > 0]
        if surface.offset_sigma_mm > 0:
            table.append(Parameter(f"surface {index} offset", SURFACE_OFFSET_KIND,
                                   surface.offset_sigma_mm))
    table += [Parameter(f"camera {name}", intrinsic_kind(name, sigma), sigma)
              for name, sigma in sorted(rig.camera_sigma.items())]
    if line:
        plane = _prior(tolerances.line_plane_deg, True)
        table += [Parameter(LINE_PLANE[0], LINE_PLANE_KIND, plane),
                  Parameter(LINE_PLANE[1], LINE_PLANE_KIND, plane),
                  Parameter(LINE_PLANE[2], LINE_OFFSET_KIND, _prior(tolerances.line_plane_mm))]
    return ParameterTable(tuple(table))


class RigModel:
    """Maps a parameter vector to a rig, to the known surfaces and to the residuals of
    observations."""

    def __init__(self, rig: Rig, laser_ids: list[int], surfaces: list[KnownSurface],
                 fit_emitters: bool = False, line: LineObservations | None = None,
                 line_plane: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """`line_plane` (unit normal, point [mm]) is where the plane's parameters start; it is
        needed with `line`."""
        self.rig = rig
        self.laser_ids = laser_ids
        self.diodes = [rig.diode(i) for i in laser_ids]
        self.surfaces = surfaces
        self.table = _parameters(rig, laser_ids, surfaces, fit_emitters, line is not None)
        names = self.table.names
        self._axes = [across_axes(d.direction) for d in self.diodes]
        self._beam_index = np.array([names.index(f"beam {i} tilt a") for i in laser_ids], int)
        self._emitter_index = np.array([names.index(f"emitter {i} a")
                                        if f"emitter {i} a" in names else -1
                                        for i in laser_ids], int)
        self._tilt_index = np.array([[names.index(f"surface {k} tilt {axis}")
                                      if f"surface {k} tilt {axis}" in names else -1
                                      for axis in "xy"] for k in range(len(surfaces))],
                                    int).reshape(-1, 2)
        self._offset_index = np.array([names.index(f"surface {k} offset")
                                       if f"surface {k} offset" in names else -1
                                       for k in range(len(surfaces))], int)
        self._tilts = np.array([[s.tilt_x_rad, s.tilt_y_rad] for s in surfaces]).reshape(-1, 2)
        self._offsets = np.array([s.offset_mm for s in surfaces], float)
        prior = self.table.prior_sigmas
        self._prior_index = np.flatnonzero(np.isfinite(prior))
        self._prior_sigma = prior[self._prior_index]
        self._intrinsics = {name: names.index(f"camera {name}") for name in rig.camera_sigma}
        self.line = line
        if line is not None:
            if line_plane is None:
                raise ValueError("line observations need a starting line plane")
            self._plane_start = line_plane
            self._plane_axes = across_axes(line_plane[0])

    @property
    def size(self) -> int:
        """Number of parameters."""
        return len(self.table)

    def intrinsics(self, x: np.ndarray) -> CameraModel:
        """The camera model for parameters `x` (the rig file's, its declared intrinsics
        changed)."""
        if not self._intrinsics:
            return self.rig.camera
        return self.rig.camera.with_intrinsics({name: float(x[k])
                                                for name, k in self._intrinsics.items()})

    def camera(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Camera-to-world rotation and camera centre [mm] for parameters `x`."""
        base = self.rig.world_to_camera.rotation.T
        return (Rotation.from_rotvec(x[:3]).as_matrix() @ base,
                self.rig.camera_position_mm + x[3:6])

    def beams(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Emitters (N×3 mm) and unit directions (N×3) for parameters `x`."""
        u = np.array([a for a, _ in self._axes]).reshape(-1, 3)
        v = np.array([b for _, b in self._axes]).reshape(-1, 3)
        base = np.array([d.direction for d in self.diodes]).reshape(-1, 3)
        tilt = x[self._beam_index[:, None] + np.arange(2)].reshape(-1, 2)
        directions = base + tilt[:, :1] * u + tilt[:, 1:] * v
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        emitters = np.array([d.emitter_mm for d in self.diodes], float).reshape(-1, 3)
        moved = self._emitter_index >= 0
        shift = x[self._emitter_index[moved][:, None] + np.arange(2)].reshape(-1, 2)
        emitters[moved] += shift[:, :1] * u[moved] + shift[:, 1:] * v[moved]
        return emitters, directions

    def surface_planes(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each known surface for parameters `x`: normals (F×3, (tan γx, tan γy, 1)) and
        offsets [mm], Z = offset − X tan γx − Y tan γy."""
        tilts = self._tilts.copy()
        read = self._tilt_index >= 0
        tilts[read] += x[self._tilt_index[read]]
        offsets = self._offsets.copy()
        level = self._offset_index >= 0
        offsets[level] += x[self._offset_index[level]]
        return np.column_stack([np.tan(tilts), np.ones(len(tilts))]), offsets

    def surfaces_at(self, x: np.ndarray) -> list[KnownSurface]:
        """The known surfaces for parameters `x` (their σ as read)."""
        normals, offsets = self.surface_planes(x)
        tilts = np.arctan(normals[:, :2])
        return [replace(s, offset_mm=float(o), tilt_x_rad=float(t[0]), tilt_y_rad=float(t[1]))
                for s, t, o in zip(self.surfaces, tilts, offsets, strict=True)]

    def hits(self, x: np.ndarray, diode: np.ndarray, frame: np.ndarray) -> np.ndarray:
        """Where each (diode, frame) beam meets that frame's known surface (N×3 mm)."""
        emitters, directions = self.beams(x)
        normals, offsets = self.surface_planes(x)
        return ray_plane_points(emitters[diode], directions[diode], normals[frame],
                                offsets[frame])

    def line_plane(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The line laser's plane for parameters `x`: unit normal and a point on it [mm]."""
        normal, point = self._plane_start
        u, v = self._plane_axes
        tilt_a, tilt_b, offset = x[-3:]
        turned = normal + tilt_a * u + tilt_b * v
        return turned / np.linalg.norm(turned), point + offset * normal

    def line_residuals(self, x: np.ndarray) -> np.ndarray:
        """Each line pixel's shift along its row [px] to where the plane meets its surface."""
        assert self.line is not None
        rotation, centre = self.camera(x)
        normal, point = self.line_plane(x)
        normals, offsets = self.surface_planes(x)
        frame = self.line.frame
        # Rays through each line pixel and its neighbour along the row.
        camera = self.intrinsics(x)
        rays = camera.pixel_to_ray(self.line.pixels)
        next_rays = camera.pixel_to_ray(self.line.pixels + np.array([1.0, 0.0]))
        here = self._distance_mm(rays @ rotation.T, centre, normals[frame],
                                 offsets[frame], normal, point)
        beside = self._distance_mm(next_rays @ rotation.T, centre, normals[frame],
                                   offsets[frame], normal, point)
        return here / (here - beside)

    @staticmethod
    def _distance_mm(rays: np.ndarray, centre: np.ndarray, surface_normals: np.ndarray,
                     surface_offsets: np.ndarray, normal: np.ndarray, point: np.ndarray
                     ) -> np.ndarray:
        """Signed distance [mm] from the plane (normal, point) of each ray's surface point."""
        hits = ray_plane_points(centre, rays, surface_normals, surface_offsets)
        return (hits - point) @ normal

    @property
    def prior_parameters(self) -> np.ndarray:
        """The parameters with a declared tolerance, in the order of `prior_residuals`."""
        return self._prior_index

    def shared_parameters(self) -> np.ndarray:
        """The parameters every spot and line pixel depends on: the camera's pose and its
        declared intrinsics."""
        return np.array([*range(6), *self._intrinsics.values()], int)

    def spot_parameters(self, diode: int, frame: int) -> np.ndarray:
        """The parameters a spot of one diode (index into `laser_ids`) on one surface (index
        into `surfaces`) depends on."""
        beam, emitter = self._beam_index[diode], self._emitter_index[diode]
        own = [beam, beam + 1, *([emitter, emitter + 1] if emitter >= 0 else [])]
        return np.array([*self.shared_parameters(), *own, *self._surface_parameters(frame)],
                        int)

    def line_parameters(self, frame: int) -> np.ndarray:
        """The parameters a line pixel on one surface depends on."""
        plane = [self.size - 3, self.size - 2, self.size - 1] if self.line is not None else []
        return np.array([*self.shared_parameters(), *self._surface_parameters(frame), *plane],
                        int)

    def _surface_parameters(self, frame: int) -> list[int]:
        """One surface's angles and fill level, where they are parameters."""
        indices = [*self._tilt_index[frame], self._offset_index[frame]]
        return [int(k) for k in indices if k >= 0]

    def prior_residuals(self, x: np.ndarray) -> np.ndarray:
        """Each declared tolerance's residual: the parameter's change in its own σ."""
        return x[self._prior_index] / self._prior_sigma

    def predict(self, x: np.ndarray, diode: np.ndarray, frame: np.ndarray) -> np.ndarray:
        """Predicted pixels (N×2) of each (diode, frame) spot."""
        rotation, centre = self.camera(x)
        points = self.hits(x, diode, frame)
        return self.intrinsics(x).project((points - centre) @ rotation)

    def to_rig(self, x: np.ndarray) -> Rig:
        """The rig with these parameters (diodes not in the model stay as they were)."""
        rotation, centre = self.camera(x)
        pose = RigidTransform(rotation.T, -rotation.T @ centre)
        emitters, directions = self.beams(x)
        fitted = {i: (e, d) for i, e, d in zip(self.laser_ids, emitters, directions,
                                                strict=True)}
        diodes = tuple(replace(d, emitter_mm=fitted[d.laser_id][0],
                               direction=fitted[d.laser_id][1]) if d.laser_id in fitted else d
                       for d in self.rig.diodes)
        line_laser = self.rig.line_laser
        if self.line is not None and line_laser is not None:
            normal, point = self.line_plane(x)
            if normal @ line_laser.normal < 0:
                normal = -normal
            emitter = line_laser.emitter_mm - ((line_laser.emitter_mm - point) @ normal) * normal
            line_laser = LineLaser(emitter, normal)
        return replace(self.rig, camera=self.intrinsics(x), world_to_camera=pose, diodes=diodes,
                       line_laser=line_laser)
