"""Pinhole camera with skew and Brown-Conrady distortion (seed Eqs. 2–5)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from sds_model.camera.model import (
    CameraModel,
    CameraModelError,
    as_points,
    scaled_pixel,
    scaled_size,
)

INTRINSICS = ("alpha_px", "beta_px", "x0_px", "y0_px", "k1", "k2", "k3", "p1", "p2")
"""The scalar intrinsics a camera file's `sigma:` may name."""
UNDISTORT_TOLERANCE = 1e-12
"""Newton undistortion stops when the distorted point is matched to this (normalised units)."""
UNDISTORT_MAX_ITERATIONS = 30
UNDISTORT_MAX_HALVINGS = 10


@dataclass(frozen=True)
class PinholeCamera(CameraModel):
    """Pinhole + Brown-Conrady camera; x = column, y = row, centre of the top-left pixel (0, 0).

    Eqs. 3–5 distort the normalised point (X/Z, Y/Z); the skew angle θ then enters through the
    matrix of Eq. 2 applied to the distorted point, as in OpenCV and ROS (K[0,1] = −α cot θ), so
    that camera_info round-trips exactly. For θ = 90° this is Eqs. 2–5 verbatim and equals
    cv2.projectPoints.
    """

    model_name: ClassVar[str] = "pinhole"

    width_px: int
    height_px: int
    alpha_px: float
    beta_px: float
    x0_px: float
    y0_px: float
    skew_angle_rad: float = math.pi / 2
    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    p1: float = 0.0
    p2: float = 0.0

    def __post_init__(self) -> None:
        if self.alpha_px <= 0 or self.beta_px <= 0:
            raise CameraModelError("alpha_px and beta_px must be positive")
        if not 0 < self.skew_angle_rad < math.pi:
            raise CameraModelError("the skew angle must lie in (0, 180) degrees")

    @classmethod
    def from_opencv(cls, camera_matrix: ArrayLike, distortion: ArrayLike, width_px: int,
                    height_px: int) -> PinholeCamera:
        """From OpenCV's K and distortion vector [k1, k2, p1, p2(, k3)]."""
        k = np.asarray(camera_matrix, dtype=float).reshape(3, 3)
        d = np.zeros(5)
        given = np.asarray(distortion, dtype=float).ravel()
        if given.size > 5 and np.any(given[5:] != 0):
            raise CameraModelError("only k1, k2, p1, p2, k3 (plumb_bob) are supported")
        d[: min(5, given.size)] = given[:5]
        if k[1, 0] != 0 or k[2, 0] != 0 or k[2, 1] != 0 or k[2, 2] != 1:
            raise CameraModelError(f"not an upper-triangular camera matrix: {k.tolist()}")
        theta = math.atan2(1.0, -k[0, 1] / k[0, 0])
        return cls(int(width_px), int(height_px), k[0, 0], k[1, 1] * math.sin(theta), k[0, 2],
                   k[1, 2], theta, k1=d[0], k2=d[1], p1=d[2], p2=d[3], k3=d[4])

    def camera_matrix(self) -> np.ndarray:
        """K of Eq. 2 (OpenCV/ROS layout): [[α, −α cot θ, x0], [0, β / sin θ, y0], [0, 0, 1]]."""
        theta = self.skew_angle_rad
        skew = 0.0 if theta == math.pi / 2 else -self.alpha_px / math.tan(theta)
        return np.array([[self.alpha_px, skew, self.x0_px],
                         [0.0, self.beta_px / math.sin(theta), self.y0_px],
                         [0.0, 0.0, 1.0]])

    def distortion_coefficients(self) -> np.ndarray:
        """OpenCV's order: [k1, k2, p1, p2, k3]."""
        return np.array([self.k1, self.k2, self.p1, self.p2, self.k3])

    def distort(self, normalised: np.ndarray) -> np.ndarray:
        """Eqs. 3–4: undistorted normalised (x'_n, y'_n) → distorted normalised coordinates."""
        x, y = normalised[:, 0], normalised[:, 1]
        r2 = x * x + y * y
        radial = 1 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        xd = x * radial + 2 * self.p1 * x * y + self.p2 * (r2 + 2 * x * x)
        yd = y * radial + self.p1 * (r2 + 2 * y * y) + 2 * self.p2 * x * y
        return np.stack([xd, yd], axis=1)

    def undistort(self, distorted: np.ndarray) -> np.ndarray:
        """Invert Eqs. 3–4 by damped Newton; NaN where no root lies on the rising branch.

        Each step is halved until it lowers the residual, so points near a strong barrel
        distortion's fold do not overshoot; converged points leave the iteration.
        """
        point = distorted.copy()
        active = np.flatnonzero(np.isfinite(distorted).all(axis=1))
        residual = self.distort(point[active]) - distorted[active]
        for _ in range(UNDISTORT_MAX_ITERATIONS):
            error = np.max(np.abs(residual), axis=1)
            moving = error > UNDISTORT_TOLERANCE
            active, residual, error = active[moving], residual[moving], error[moving]
            if active.size == 0:
                break
            j11, j12, j21, j22 = self._jacobian(point[active])
            det = j11 * j22 - j12 * j21
            step = np.stack([(j22 * residual[:, 0] - j12 * residual[:, 1]) / det,
                             (j11 * residual[:, 1] - j21 * residual[:, 0]) / det], axis=1)
            for _ in range(UNDISTORT_MAX_HALVINGS):
                trial = point[active] - step
                trial_residual = self.distort(trial) - distorted[active]
                worse = ~(np.max(np.abs(trial_residual), axis=1) < error)
                if not worse.any():
                    break
                step[worse] *= 0.5
            point[active] = trial
            # A point no step improves has stalled (beyond the fold): it leaves, unconverged.
            active, residual = active[~worse], trial_residual[~worse]
        final = np.max(np.abs(self.distort(point) - distorted), axis=1)
        point[~(final <= UNDISTORT_TOLERANCE) | ~self._on_rising_branch(point)] = np.nan
        return point

    def _on_rising_branch(self, point: np.ndarray) -> np.ndarray:
        """True where the radial distortion r (1 + k1 r² + ...) is positive and still rising.

        Past the fold of a strong barrel distortion, Eq. 3 maps far points back into the image
        (mirrored); such roots are not the ray that made the pixel.
        """
        r2 = np.sum(point * point, axis=1)
        radial = 1 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        slope = self.k1 + r2 * (2 * self.k2 + 3 * self.k3 * r2)
        return (radial > 0) & (radial + 2 * r2 * slope > 0)

    def _jacobian(self, point: np.ndarray) -> tuple[np.ndarray, ...]:
        """Partial derivatives of Eqs. 3–4 with respect to (x'_n, y'_n)."""
        x, y = point[:, 0], point[:, 1]
        r2 = x * x + y * y
        radial = 1 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        slope = self.k1 + r2 * (2 * self.k2 + 3 * self.k3 * r2)
        cross = 2 * x * y * slope + 2 * self.p1 * x + 2 * self.p2 * y
        return (radial + 2 * x * x * slope + 2 * self.p1 * y + 6 * self.p2 * x, cross, cross,
                radial + 2 * y * y * slope + 6 * self.p1 * y + 2 * self.p2 * x)

    def project(self, points: ArrayLike) -> np.ndarray:
        """Eqs. 2–5: camera-frame points → distorted pixels; NaN behind the camera (Z ≤ 0)."""
        points = as_points(points, 3)
        with np.errstate(divide="ignore", invalid="ignore"):
            normalised = points[:, :2] / points[:, 2:3]
        normalised[~(points[:, 2] > 0)] = np.nan
        distorted = self.distort(normalised)
        k = self.camera_matrix()
        return distorted @ k[:2, :2].T + k[:2, 2]

    def pixel_to_ray(self, pixels: ArrayLike) -> np.ndarray:
        """Distorted pixels → unit rays (Z > 0), by inverting Eq. 2 and then Eqs. 3–4."""
        pixels = as_points(pixels, 2)
        k = self.camera_matrix()
        distorted = (pixels - k[:2, 2]) @ np.linalg.inv(k[:2, :2]).T
        normalised = self.undistort(distorted)
        rays = np.column_stack([normalised, np.ones(len(normalised))])
        return rays / np.linalg.norm(rays, axis=1, keepdims=True)

    def scaled(self, factor: float) -> PinholeCamera:
        """Focal lengths and centre scale with the image; the distortion does not change."""
        return replace(self, width_px=scaled_size(self.width_px, factor),
                       height_px=scaled_size(self.height_px, factor),
                       alpha_px=self.alpha_px * factor, beta_px=self.beta_px * factor,
                       x0_px=scaled_pixel(self.x0_px, factor),
                       y0_px=scaled_pixel(self.y0_px, factor))

    def intrinsics(self) -> dict[str, float]:
        """α, β, the centre (Eq. 2) and the distortion terms (Eqs. 3–4) by field name."""
        return {name: float(getattr(self, name)) for name in INTRINSICS}

    def with_intrinsics(self, changes: Mapping[str, float]) -> PinholeCamera:
        """The camera with the named intrinsics changed by the given amounts."""
        return replace(self, **{name: getattr(self, name) + changes[name]
                                for name in INTRINSICS if name in changes})

    def parameters(self) -> dict[str, Any]:
        """Eq. 2 intrinsics [px] and θ [deg]; Eqs. 3–4 distortion."""
        return {
            "alpha_px": float(self.alpha_px), "beta_px": float(self.beta_px),
            "centre_px": [float(self.x0_px), float(self.y0_px)],
            "skew_angle_deg": math.degrees(self.skew_angle_rad),
            "distortion": {"k1": float(self.k1), "k2": float(self.k2), "k3": float(self.k3),
                           "p1": float(self.p1), "p2": float(self.p2)},
        }

    @classmethod
    def from_parameters(cls, parameters: dict[str, Any], width_px: int, height_px: int,
                        pixel_origin: int) -> PinholeCamera:
        """From a camera file's `parameters` mapping."""
        x0, y0 = (float(v) - pixel_origin for v in parameters["centre_px"])
        distortion = {key: float(value) for key, value in parameters.get("distortion", {}).items()}
        unknown = set(distortion) - {"k1", "k2", "k3", "p1", "p2"}
        if unknown:
            raise CameraModelError(f"unknown distortion terms {sorted(unknown)}")
        theta = math.radians(float(parameters.get("skew_angle_deg", 90.0)))
        return cls(width_px, height_px, float(parameters["alpha_px"]), float(parameters["beta_px"]),
                   x0, y0, theta, **distortion)
