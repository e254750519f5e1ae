"""The rig's calibratable geometry as one parameter vector, and its pixel residuals.

Parameters (natural units, each a small change from the rig file's value):
camera rotation about the world X, Y, Z axes [rad] and centre shift [mm]; per beam two tilts
of its direction [rad] and (optionally) two shifts of its emitter across the beam [mm] (along
the beam an emitter shift changes nothing); with line observations, two tilts of the line
laser's plane about a point on it [rad] and its shift along its normal [mm]. Spots are
predicted as the beam's hit on the frame's known surface (Eq. 9 with Z = g(X, Y) known),
projected through the camera (Eq. 1 and the camera model). A line pixel's residual is the
shift along its image row [px] that puts its ray's hit on the known surface into the plane.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation
from sds_model.geometry import RigidTransform
from sds_model.rig import LineLaser, Rig

from sds_recon.calibration.lasers import KnownSurface

CAMERA_ROTATION = ("camera rotation about X", "camera rotation about Y",
                   "camera rotation about Z")
CAMERA_SHIFT = ("camera X", "camera Y", "camera Z")
LINE_PLANE = ("line plane tilt a", "line plane tilt b", "line plane offset")


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


def _across(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to `direction` and to each other."""
    helper = np.array([0.0, 0.0, 1.0]) if abs(direction[2]) < 0.9 else np.array([1.0, 0, 0])
    first = np.cross(helper, direction)
    first /= np.linalg.norm(first)
    return first, np.cross(direction, first)


class RigModel:
    """Maps a parameter vector to a rig and to the weighted residuals of observations."""

    def __init__(self, rig: Rig, laser_ids: list[int], surfaces: list[KnownSurface],
                 fit_emitters: bool = False, line: LineObservations | None = None,
                 line_plane: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """`line_plane` (unit normal, point [mm]) is where the plane's parameters start; it is
        needed with `line`."""
        self.rig = rig
        self.laser_ids = laser_ids
        self.diodes = [rig.diode(i) for i in laser_ids]
        self.surfaces = surfaces
        self.fit_emitters = fit_emitters
        self._axes = [_across(d.direction) for d in self.diodes]
        normals = np.array([[np.tan(s.tilt_x_rad), np.tan(s.tilt_y_rad), 1.0] for s in surfaces])
        self._normals = normals.reshape(-1, 3)
        self._offsets = np.array([s.offset_mm for s in surfaces])
        self.names: list[str] = [*CAMERA_ROTATION, *CAMERA_SHIFT]
        self.scales: list[float] = [np.radians(1.0)] * 3 + [1.0] * 3
        for i in laser_ids:
            self.names += [f"beam {i} tilt a", f"beam {i} tilt b"]
            self.scales += [np.radians(1.0)] * 2
            if fit_emitters:
                self.names += [f"emitter {i} a", f"emitter {i} b"]
                self.scales += [1.0, 1.0]
        self._per_beam = 4 if fit_emitters else 2
        self.line = line
        if line is not None:
            if line_plane is None:
                raise ValueError("line observations need a starting line plane")
            self._plane_start = line_plane
            self._plane_axes = _across(line_plane[0])
            camera = rig.camera
            # Rays through each line pixel and its neighbour along the row, camera frame:
            # fixed, since the intrinsics are not fitted.
            self._line_rays = camera.pixel_to_ray(line.pixels)
            self._next_rays = camera.pixel_to_ray(line.pixels + np.array([1.0, 0.0]))
            self.names += list(LINE_PLANE)
            self.scales += [np.radians(1.0)] * 2 + [1.0]

    @property
    def size(self) -> int:
        """Number of parameters."""
        return len(self.names)

    def camera(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Camera-to-world rotation and camera centre [mm] for parameters `x`."""
        base = self.rig.world_to_camera.rotation.T
        return (Rotation.from_rotvec(x[:3]).as_matrix() @ base,
                self.rig.camera_position_mm + x[3:6])

    def beams(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Emitters (N×3 mm) and unit directions (N×3) for parameters `x`."""
        values = x[6:6 + self._per_beam * len(self.diodes)].reshape(len(self.diodes), -1)
        emitters, directions = [], []
        for diode, (u, v), row in zip(self.diodes, self._axes, values, strict=True):
            direction = diode.direction + row[0] * u + row[1] * v
            directions.append(direction / np.linalg.norm(direction))
            emitter = diode.emitter_mm + (row[2] * u + row[3] * v if self.fit_emitters else 0)
            emitters.append(emitter)
        return np.array(emitters).reshape(-1, 3), np.array(directions).reshape(-1, 3)

    def hits(self, x: np.ndarray, diode: np.ndarray, frame: np.ndarray) -> np.ndarray:
        """Where each (diode, frame) beam meets that frame's known surface (N×3 mm)."""
        emitters, directions = self.beams(x)
        start, d = emitters[diode], directions[diode]
        m, offset = self._normals[frame], self._offsets[frame]
        s = (offset - np.sum(start * m, axis=1)) / np.sum(d * m, axis=1)
        return start + s[:, None] * d

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
        frame = self.line.frame
        m, offset = self._normals[frame], self._offsets[frame]

        def distance_mm(rays: np.ndarray) -> np.ndarray:
            world = rays @ rotation.T
            s = (offset - centre @ m.T) / np.sum(world * m, axis=1)
            return (centre + s[:, None] * world - point) @ normal

        here = distance_mm(self._line_rays)
        return here / (here - distance_mm(self._next_rays))

    def predict(self, x: np.ndarray, diode: np.ndarray, frame: np.ndarray) -> np.ndarray:
        """Predicted pixels (N×2) of each (diode, frame) spot."""
        rotation, centre = self.camera(x)
        points = self.hits(x, diode, frame)
        return self.rig.camera.project((points - centre) @ rotation)

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
        return replace(self.rig, world_to_camera=pose, diodes=diodes, line_laser=line_laser)

