"""Laser beams and the line laser's plane from images of known surfaces (seed Sec. 3.3.1)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike
from sds_model.camera.model import CameraModel
from sds_model.errors import InputError
from sds_model.geometry import RigidTransform, ray_plane_points
from sds_model.rig import Rig

HUBER_MM = 0.2
"""Residual beyond which the plane fit down-weights a line point (robust to stray pixels)."""
OUTLIER_MM = 1.0
"""Residual beyond which a line point is left out of the plane fit (the line's ends on the
container wall, a reflection taken for the line): Huber weights alone let a few such points
tip the plane, since they sit far out along its least determined direction."""
CONSENSUS_TRIALS = 300
"""Random point triples tried for the plane the most points agree with (the fit's start)."""
CONSENSUS_POINTS = 2000
"""Points (a random subset of more) that vote for a consensus plane."""


@dataclass(frozen=True)
class KnownSurface:
    """A flat liquid surface of known pose: Z = offset − X tan γx − Y tan γy (world, mm), and
    how well it is known: σ of γx, of γy [rad] and of its offset [mm] (0: exact)."""

    offset_mm: float = 0.0
    tilt_x_rad: float = 0.0
    tilt_y_rad: float = 0.0
    tilt_x_sigma_rad: float = 0.0
    tilt_y_sigma_rad: float = 0.0
    offset_sigma_mm: float = 0.0

    @property
    def is_level(self) -> bool:
        """Whether both its angles are 0 (a level frame)."""
        return self.tilt_x_rad == 0.0 and self.tilt_y_rad == 0.0

    @property
    def tilted_about_x(self) -> bool:
        """Whether γx is the angle the table was set to (the larger of the two), γy the one
        across the table's axis."""
        return abs(self.tilt_x_rad) >= abs(self.tilt_y_rad)

    @property
    def has_sigma(self) -> bool:
        """Whether any of its angles or its offset was read with a σ (is not exact)."""
        return bool(self.tilt_x_sigma_rad or self.tilt_y_sigma_rad or self.offset_sigma_mm)

    def intersect(self, origin: np.ndarray, rays: np.ndarray) -> np.ndarray:
        """Where rays from `origin` meet this surface (N×3 mm); NaN for rays that miss it."""
        normal = np.array([np.tan(self.tilt_x_rad), np.tan(self.tilt_y_rad), 1.0])
        return ray_plane_points(origin, rays, normal, self.offset_mm)


@dataclass(frozen=True)
class Accuracy:
    """How well the user reads each kind of known surface (one σ each)."""

    table_deg: float = 0.5 / np.sqrt(3.0)   # a tilted frame's angle about the table's axis
                                             # (the seed: ±0.5°)
    table_across_deg: float | None = None    # its other angle, across the axis (None: as
                                             # table_deg; the table's own alignment)
    level_deg: float = 0.05                  # both angles of a level frame (a spirit level)
    fill_mm: float = 0.05                    # a fill level (a measured volume)

    @property
    def across_axis_deg(self) -> float:
        """σ of a tilted frame's angle across the table's axis [deg]."""
        return self.table_deg if self.table_across_deg is None else self.table_across_deg

    def declare(self, surface: KnownSurface) -> KnownSurface:
        """The surface with the σ its kind is read to: a tilted frame's larger angle is the one
        set about the table's axis. The first fill level is the world's Z = 0 and a tilt keeps
        the liquid's volume: only another fill level is uncertain."""
        if surface.is_level:
            sigma_x_deg = sigma_y_deg = self.level_deg
        elif surface.tilted_about_x:
            sigma_x_deg, sigma_y_deg = self.table_deg, self.across_axis_deg
        else:
            sigma_x_deg, sigma_y_deg = self.across_axis_deg, self.table_deg
        return replace(surface, tilt_x_sigma_rad=float(np.radians(sigma_x_deg)),
                       tilt_y_sigma_rad=float(np.radians(sigma_y_deg)),
                       offset_sigma_mm=self.fill_mm if surface.offset_mm != 0.0 else 0.0)

    def with_inclinometer(self, sigma_deg: float) -> Accuracy:
        """The tilted frames' two angles read to `sigma_deg` (each as before, if better)."""
        return replace(self, table_deg=min(self.table_deg, sigma_deg),
                       table_across_deg=min(self.across_axis_deg, sigma_deg))


@dataclass(frozen=True)
class BeamFit:
    """One calibrated beam: direction, emitter, RMS distance of its points, direction σ [rad]."""

    laser_id: int
    emitter_mm: np.ndarray
    direction: np.ndarray
    rms_mm: float
    direction_sigma_rad: float
    point_count: int


@dataclass(frozen=True)
class PlaneFitResult:
    """The line laser's fitted plane: unit normal, a point on it, RMS distance of its points."""

    normal: np.ndarray
    point_mm: np.ndarray
    rms_mm: float                 # of the points kept
    point_count: int
    rejected: int = 0             # points farther than OUTLIER_MM, left out


def surface_points(rig: Rig, pixels: ArrayLike, surface: KnownSurface) -> np.ndarray:
    """Camera rays through the pixels, ended on the known surface (N×3 mm)."""
    rays = rig.pixel_rays(np.atleast_2d(np.asarray(pixels, dtype=float)))
    return surface.intersect(rig.camera_position_mm, rays)


def fit_beam(laser_id: int, points_mm: np.ndarray, emitter_mm: np.ndarray,
             fit_emitter: bool = False) -> BeamFit:
    """Beam through the points: from the known emitter, or a free line (emitter moved onto it).

    With the emitter known, the direction is the principal axis of the moments of P − l about
    l, so points far along the beam weigh most; its σ follows from the perpendicular scatter.
    """
    points = points_mm[np.isfinite(points_mm).all(axis=1)]
    if len(points) < 2:
        raise InputError(f"beam {laser_id}: needs 2 or more points on known surfaces, "
                         f"got {len(points)}")
    origin = points.mean(axis=0) if fit_emitter else emitter_mm
    offsets = points - origin
    direction = np.linalg.eigh(offsets.T @ offsets)[1][:, -1]
    if direction[2] > 0:
        direction = -direction     # beams point down, towards the liquid
    along = offsets @ direction
    perpendicular = offsets - along[:, None] * direction
    distances = np.linalg.norm(perpendicular, axis=1)
    spread = along - along.mean() if fit_emitter else along
    dof = max(len(points) - (4 if fit_emitter else 2), 1)
    sigma_perp = np.sqrt(np.sum(distances**2) / dof)
    emitter = origin + ((emitter_mm - origin) @ direction) * direction if fit_emitter else origin
    return BeamFit(laser_id, emitter, direction, float(np.sqrt(np.mean(distances**2))),
                   float(sigma_perp / np.sqrt(np.sum(spread**2))), len(points))


def calibrate_beams(rig: Rig, laser_ids: ArrayLike, pixels: ArrayLike,
                    surfaces: list[KnownSurface], fit_emitter: bool = False) -> list[BeamFit]:
    """Every beam from its spots on known surfaces (one surface per observation), jointly."""
    ids = np.asarray(laser_ids, dtype=int)
    pixels = np.atleast_2d(np.asarray(pixels, dtype=float))
    points = np.full((len(ids), 3), np.nan)
    for surface in set(surfaces):
        chosen = np.array([s == surface for s in surfaces])
        points[chosen] = surface_points(rig, pixels[chosen], surface)
    return [fit_beam(d.laser_id, points[ids == d.laser_id], d.emitter_mm, fit_emitter)
            for d in rig.diodes if np.any(ids == d.laser_id)]


def consensus_plane(points_mm: np.ndarray, tolerance_mm: float = OUTLIER_MM,
                    trials: int = CONSENSUS_TRIALS, near: np.ndarray | None = None,
                    cone_deg: float = 90.0) -> tuple[np.ndarray, np.ndarray]:
    """Unit normal and point of the plane through three of the points with the least truncated
    squared distance of all points (each counted up to `tolerance_mm`; random sample consensus
    scored as MSAC, seeded: the same points give the same plane). With `near`, only planes
    whose normal is within `cone_deg` of it are tried."""
    rng = np.random.default_rng(0)
    triples = rng.integers(0, len(points_mm), (trials, 3))
    a, b, c = points_mm[triples[:, 0]], points_mm[triples[:, 1]], points_mm[triples[:, 2]]
    normals = np.cross(b - a, c - a)
    length = np.linalg.norm(normals, axis=1)
    usable = length > 1e-9
    normals = normals[usable] / length[usable, None]
    a = a[usable]
    if near is not None:
        usable = np.abs(normals @ near) >= np.cos(np.radians(cone_deg))
        normals, a = normals[usable], a[usable]
    if not len(normals):
        raise InputError("no three of the points span a plane"
                         + ("" if near is None else f" within {cone_deg}° of the expected one"))
    scored = points_mm[rng.permutation(len(points_mm))[:CONSENSUS_POINTS]]
    distances = np.abs((scored[None] - a[:, None]) @ normals[..., None])[..., 0]
    best = int(np.argmin(np.sum(np.minimum(distances, tolerance_mm) ** 2, axis=1)))
    return normals[best], a[best]


def fit_plane_robust(points_mm: np.ndarray, iterations: int = 20, near: np.ndarray | None = None,
                     cone_deg: float = 90.0) -> PlaneFitResult:
    """Plane through 3-D points: started from the consensus plane (with `near`, one within
    `cone_deg` of that normal), then iteratively reweighted total least squares (Huber
    weights) over the points within OUTLIER_MM of it."""
    points = points_mm[np.isfinite(points_mm).all(axis=1)]
    if len(points) < 3:
        raise InputError(f"a plane needs 3 or more points, got {len(points)}")
    normal, centre = consensus_plane(points, near=near, cone_deg=cone_deg)
    for _ in range(iterations):
        residual = np.abs((points - centre) @ normal)
        weights = np.where(residual <= HUBER_MM, 1.0, HUBER_MM / np.maximum(residual, 1e-12))
        weights[residual > OUTLIER_MM] = 0.0
        centre = np.average(points, axis=0, weights=weights)
        offsets = points - centre
        normal = np.linalg.eigh((offsets * weights[:, None]).T @ offsets)[1][:, 0]
    distances = (points - centre) @ normal
    kept = np.abs(distances) <= OUTLIER_MM
    return PlaneFitResult(normal, centre, float(np.sqrt(np.mean(distances[kept] ** 2))),
                          int(kept.sum()), int((~kept).sum()))


def points_on_surfaces(rig: Rig, pixels: ArrayLike, surfaces: list[KnownSurface]
                       ) -> np.ndarray:
    """Camera rays through the pixels, each ended on its own known surface (N×3 mm)."""
    pixels = np.atleast_2d(np.asarray(pixels, dtype=float))
    points = np.full((len(pixels), 3), np.nan)
    for surface in set(surfaces):
        chosen = np.array([s == surface for s in surfaces])
        points[chosen] = surface_points(rig, pixels[chosen], surface)
    return points


def calibrate_line_plane(rig: Rig, pixels: ArrayLike, surfaces: list[KnownSurface],
                         cone_deg: float = 90.0) -> PlaneFitResult:
    """The line laser's plane from its pixels on known surfaces (one surface per pixel), its
    normal within `cone_deg` of the rig file's."""
    points = points_on_surfaces(rig, pixels, surfaces)
    near = None if rig.line_laser is None else rig.line_laser.normal
    result = fit_plane_robust(points, near=near, cone_deg=cone_deg)
    if rig.line_laser is not None and result.normal @ rig.line_laser.normal < 0:
        result = replace(result, normal=-result.normal)
    return result


def board_points(camera: CameraModel, board_to_camera: RigidTransform, pixels: ArrayLike
                 ) -> np.ndarray:
    """Camera rays through the pixels, ended on a board's plane Z = 0 (N×3 mm, camera frame)."""
    rays = camera.pixel_to_ray(np.atleast_2d(np.asarray(pixels, dtype=float)))
    normal = board_to_camera.rotation[:, 2]
    return ray_plane_points(np.zeros(3), rays, normal, normal @ board_to_camera.translation_mm)


def calibrate_line_plane_on_boards(camera: CameraModel, poses: list[RigidTransform],
                                   pixels: list[np.ndarray]) -> PlaneFitResult:
    """The line laser's plane in the camera frame from its pixels on boards of known pose.

    The seed's known-surface calibration (Sec. 3.3.1) with a checkerboard as the surface:
    each board pose (from the camera calibration) puts the line's pixels in 3-D.
    """
    if len(poses) != len(pixels):
        raise InputError(f"{len(poses)} board poses but {len(pixels)} line pixel sets")
    if len(poses) < 2:
        raise InputError("a line plane needs the line on 2 or more board poses")
    points = np.vstack([board_points(camera, pose, p) for pose, p in zip(poses, pixels,
                                                                          strict=True)])
    return fit_plane_robust(points)
