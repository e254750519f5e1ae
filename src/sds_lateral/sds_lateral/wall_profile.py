"""The liquid's height along the container wall, seen from the side, per frame [mm].

The opaque liquid fills the wall dark up to its contact line; above it the side camera looks
through the empty part of the container at a bright background. In each image column that
sees the front wall at less than `max_incidence_deg`, the contact line is the strongest
bright-to-dark step going down a band around the flat level; its row is where the column's
brightness crosses halfway between the levels above and below it (sub-pixel, linear between
the two pixels around it). That pixel's ray, from the calibrated camera (model and pose),
meets the wall — the cylinder of the container's inner radius — where the liquid touches it.

Assumptions, stated because a real container departs from them: the wall is thin (its
refraction is not modelled), the camera looks at it from below the liquid's level so that
no part of the surface behind the wall rises into the line of sight above the contact line
(true while the surface's rise along the view, front to back, stays under the rays' climb:
about 6 mm across the 110 mm container for a camera 20 mm low at 400 mm).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter1d
from sds_model.camera.model import CameraModel
from sds_model.errors import InputError
from sds_model.geometry import RigidTransform

from sds_lateral.board import (
    POSE_STEP,
    BoardPose,
    perturbed_pose,
    placement_sigma_mm,
    solve_pose,
)

BAND_MM = 15.0
"""Half-height of the band searched for the contact line around the flat level [mm]."""
MAX_INCIDENCE_DEG = 60.0
"""Columns that see the wall more obliquely than this are left out (their mm per px grows as
1 / cos, and the wall's refraction with it)."""
MIN_CONTRAST = 30.0
"""Brightness levels between the liquid below and the background above an edge (8-bit)."""
LEVEL_ROWS = (4, 10)
"""The levels are the medians of the rows this far above and below the steepest step [px]."""
SMOOTHING_PX = 1.0
"""Gaussian σ along a column before the steepest step is looked for [px]."""
WALL_SAMPLES = 721
"""Azimuths sampled to map image columns onto the wall."""


@dataclass(frozen=True)
class WallProfile:
    """One frame's contact line: per image column, its sub-pixel row (NaN: no edge found), the
    wall point where that pixel's ray meets the wall [mm, world], the point's azimuth [rad],
    the σ of its height from the image's noise [mm] (independent from frame to frame) and from
    the camera pose [mm] (the same error in every frame)."""

    column_px: np.ndarray
    edge_row_px: np.ndarray
    wall_mm: np.ndarray
    azimuth_rad: np.ndarray
    sigma_z_mm: np.ndarray
    pose_sigma_z_mm: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        """The columns where the contact line was found."""
        return np.isfinite(self.edge_row_px)


class WallProfiler:
    """Finds the contact line in frames of one calibrated side camera (geometry computed once)."""

    def __init__(self, camera: CameraModel, world_to_camera: RigidTransform, radius_mm: float,
                 pose: BoardPose | None = None,
                 band_mm: float = BAND_MM, max_incidence_deg: float = MAX_INCIDENCE_DEG) -> None:
        """`pose`: the board measurement `world_to_camera` came from; its covariance and the
        board's placement σ are carried into every height's σ (None: the pose is exact)."""
        self.camera = camera
        self.world_to_camera = world_to_camera
        self.radius_mm = radius_mm
        self.centre_mm = world_to_camera.inverse().translation_mm
        azimuth = np.linspace(-np.pi, np.pi, WALL_SAMPLES)
        normal = np.column_stack([np.cos(azimuth), np.sin(azimuth), np.zeros_like(azimuth)])
        wall = radius_mm * normal
        towards = self.centre_mm - wall
        cosine = np.sum(normal * towards, axis=1) / np.linalg.norm(towards, axis=1)
        seen = cosine > np.cos(np.radians(max_incidence_deg))
        if not np.any(seen):
            raise InputError("the side camera sees no part of the wall within "
                             f"{max_incidence_deg:g} degrees of its normal")
        rows = {}
        for height in (-band_mm, 0.0, band_mm):
            pixels = camera.project(world_to_camera.apply(wall[seen] + [0.0, 0.0, height]))
            rows[height] = pixels
        finite = np.isfinite(np.column_stack(list(rows.values()))).all(axis=1)
        if not np.any(finite):
            raise InputError("the side camera's image holds no part of the wall's band")
        columns_seen = rows[0.0][finite, 0]
        order = np.argsort(columns_seen)
        first, last = columns_seen[order[0]], columns_seen[order[-1]]
        columns = np.arange(max(np.ceil(first), 0), min(np.floor(last), camera.width_px - 1) + 1)
        top = np.interp(columns, columns_seen[order], rows[band_mm][finite][order, 1])
        bottom = np.interp(columns, columns_seen[order], rows[-band_mm][finite][order, 1])
        self.column_px = columns.astype(int)
        self.top_row = np.clip(np.floor(np.minimum(top, bottom)), 0, camera.height_px - 1)
        self.band_rows = int(np.ceil(np.max(np.abs(bottom - top)))) + 2
        rest_row = np.interp(columns, columns_seen[order], rows[0.0][finite][order, 1])
        self.pose_sigma_z_mm = (np.zeros(len(columns)) if pose is None
                                else self._pose_sigma_z(columns, rest_row, pose))

    def _pose_sigma_z(self, columns: np.ndarray, rows: np.ndarray, pose: BoardPose
                      ) -> np.ndarray:
        """σ of each column's wall height at the flat level [mm]: the pose's covariance from
        the corners (its Jacobian by finite differences), each intrinsic's σ (the pose solved
        again with it moved, the rays with it: the two largely cancel) and the board's
        placement σ (boards placed δ high put every height δ high)."""
        pixels = np.column_stack([columns, rows])

        def heights(camera: CameraModel, transform: RigidTransform) -> np.ndarray:
            rays = camera.pixel_to_ray(pixels) @ transform.rotation
            return cylinder_points(transform.inverse().translation_mm, rays,
                                   self.radius_mm)[:, 2]

        jacobian = np.column_stack([
            (heights(self.camera, perturbed_pose(self.world_to_camera, step))
             - heights(self.camera, perturbed_pose(self.world_to_camera, -step)))
            / (2 * POSE_STEP) for step in np.eye(6) * POSE_STEP])
        variance = np.einsum("ij,jk,ik->i", jacobian, pose.covariance, jacobian)
        for name, sigma in pose.camera_sigma.items():
            moved = []
            for sign in (1.0, -1.0):
                camera = self.camera.with_intrinsics({name: sign * sigma})
                moved.append(heights(camera, solve_pose(pose.corners_px, pose.corners_mm,
                                                        camera)))
            variance += ((moved[0] - moved[1]) / 2) ** 2
        return np.sqrt(np.maximum(variance, 0.0) + placement_sigma_mm(pose.boards) ** 2)

    def profile(self, image: np.ndarray) -> WallProfile:
        """The contact line in one frame (grey or BGR, the camera's full image)."""
        grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        rows = self.top_row[None, :].astype(int) + np.arange(self.band_rows)[:, None]
        rows = np.clip(rows, 0, grey.shape[0] - 1)
        window = grey[rows, self.column_px[None, :]].astype(np.float32)
        smooth = gaussian_filter1d(window, SMOOTHING_PX, axis=0)
        step = np.argmin(np.diff(smooth, axis=0), axis=0)          # between step and step + 1
        near, far = LEVEL_ROWS
        above = self._take(window, step[None, :] - np.arange(near, far)[:, None])
        below = self._take(window, step[None, :] + 1 + np.arange(near, far)[:, None])
        bright, dark = np.median(above, axis=0), np.median(below, axis=0)
        noise = 1.4826 * np.median(np.abs(above - bright), axis=0)
        half = (bright + dark) / 2
        offsets = np.arange(-near + 1, near + 1)
        around = self._take(window, step[None, :] + offsets[:, None])
        under = around < half
        crossing = np.argmax(under, axis=0)                        # the first row below half
        upper = np.take_along_axis(around, np.maximum(crossing - 1, 0)[None, :], 0)[0]
        lower = np.take_along_axis(around, crossing[None, :], 0)[0]
        drop = upper - lower
        good = (bright - dark > MIN_CONTRAST) & (crossing > 0) & under.any(axis=0) & (drop > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            fraction = (upper - half) / drop
            edge = self.top_row + step + offsets[0] + crossing - 1 + fraction
            sigma_px = np.maximum(noise, 0.5) / drop
        edge = np.where(good, edge, np.nan)
        wall = self.wall_points(self.column_px, edge)
        below_wall = self.wall_points(self.column_px, edge + 1.0)
        sigma_z = np.abs(below_wall[:, 2] - wall[:, 2]) * sigma_px
        azimuth = np.arctan2(wall[:, 1], wall[:, 0])
        return WallProfile(self.column_px.astype(float), edge, wall, azimuth, sigma_z,
                           self.pose_sigma_z_mm)

    @staticmethod
    def _take(window: np.ndarray, rows: np.ndarray) -> np.ndarray:
        return np.take_along_axis(window, np.clip(rows, 0, window.shape[0] - 1), axis=0)

    def wall_points(self, column_px: np.ndarray, row_px: np.ndarray) -> np.ndarray:
        """Where the pixels' rays first meet the wall (N×3 mm, world; NaN where they miss)."""
        pixels = np.column_stack([column_px, row_px]).astype(float)
        rays = self.camera.pixel_to_ray(pixels) @ self.world_to_camera.rotation   # Rᵀ r
        return cylinder_points(self.centre_mm, rays, self.radius_mm)


def cylinder_points(origin_mm: np.ndarray, rays: np.ndarray, radius_mm: float) -> np.ndarray:
    """Where rays (N×3) from `origin_mm` (outside) first meet the vertical cylinder of
    `radius_mm` about the world Z axis (N×3 mm; NaN where they miss it)."""
    a = rays[:, 0] ** 2 + rays[:, 1] ** 2
    b = 2 * (origin_mm[0] * rays[:, 0] + origin_mm[1] * rays[:, 1])
    c = origin_mm[0] ** 2 + origin_mm[1] ** 2 - radius_mm**2
    with np.errstate(invalid="ignore", divide="ignore"):
        distance = (-b - np.sqrt(b**2 - 4 * a * c)) / (2 * a)
    distance = np.where(distance > 0, distance, np.nan)
    return origin_mm + distance[:, None] * rays
