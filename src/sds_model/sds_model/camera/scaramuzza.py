"""Scaramuzza's omnidirectional camera model (seed Eqs. 6–7)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np
from numpy.polynomial import polynomial
from numpy.typing import ArrayLike

from sds_model.camera.model import (
    CameraModel,
    CameraModelError,
    as_points,
    scaled_pixel,
    scaled_size,
)

PROJECTION_TOLERANCE_PX = 1e-10
"""Newton's root solve of the projection stops when the radius moves less than this [px]."""
PROJECTION_MAX_ITERATIONS = 12
TABLE_SAMPLES = 4097


@dataclass(frozen=True)
class ScaramuzzaCamera(CameraModel):
    """Ray = (x' − x0, y' − y0, a0 + a2 r'² + a3 r'³ + a4 r'⁴) (Eq. 6); pixel = Q p_u (Eq. 7).

    x = column, y = row, centre of the top-left pixel at (0, 0); the optical axis is +z (a0 > 0,
    as in MATLAB and the seed's Table 2). `polynomial` is ascending [a0, a1, a2, ...] with a1 = 0
    in the usual fit. Q = [[c, e], [m, 1]] acts on offsets from the centre (x0, y0).

    Projection solves for the radius r' whose ray makes the point's angle with the axis: a
    monotone lookup table gives the start, Newton's method the root, so it is exact to
    PROJECTION_TOLERANCE_PX wherever the model is one-to-one (radii up to `max_radius_px`).
    """

    model_name: ClassVar[str] = "scaramuzza"

    width_px: int
    height_px: int
    polynomial: tuple[float, ...]
    x0_px: float
    y0_px: float
    c: float = 1.0
    e: float = 0.0
    m: float = 0.0
    max_radius_px: float = field(init=False)
    _radius_table: np.ndarray = field(init=False, repr=False, compare=False)
    _angle_table: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        coefficients = tuple(float(a) for a in self.polynomial)
        if len(coefficients) < 2:
            raise CameraModelError("the polynomial needs at least a0 and one more term")
        object.__setattr__(self, "polynomial", coefficients)
        if abs(self.c - self.e * self.m) < 1e-9:
            raise CameraModelError("the stretch matrix [[c, e], [m, 1]] is singular")
        corners = np.array([[0, 0], [self.width_px - 1, 0], [0, self.height_px - 1],
                            [self.width_px - 1, self.height_px - 1]], dtype=float)
        image_radius = float(np.max(np.linalg.norm(self.unstretch(corners), axis=1)))
        radii = np.linspace(0.0, 1.05 * image_radius, TABLE_SAMPLES)
        angles = np.arctan2(radii, polynomial.polyval(radii, coefficients))
        rising = np.diff(angles) > 0
        end = len(radii) if rising.all() else int(np.argmin(rising)) + 1
        object.__setattr__(self, "max_radius_px", float(radii[end - 1]))
        object.__setattr__(self, "_radius_table", radii[:end])
        object.__setattr__(self, "_angle_table", angles[:end])

    @property
    def stretch(self) -> np.ndarray:
        """Q of Eq. 7 without its translation: distorted offset = Q · undistorted offset."""
        return np.array([[self.c, self.e], [self.m, 1.0]])

    @property
    def covers_image(self) -> bool:
        """True when the model is one-to-one over the whole image (and a margin of 5 %)."""
        return len(self._radius_table) == TABLE_SAMPLES

    def with_symmetric_stretch(self) -> tuple[ScaramuzzaCamera, float]:
        """The same image formation with e = m, and the roll [rad] it moves into the extrinsics.

        Q = S R(roll) (polar decomposition): rotating every ray about the optical axis by the
        roll and stretching by S forms the same image, so only S is an intrinsic property; c, e
        and m of two calibrations compare only in this form. S is rescaled to S[1,1] = 1, which
        rescales the polynomial: a_i' = a_i s^(1 - i).
        """
        u, sigma, vt = np.linalg.svd(self.stretch)
        symmetric, rotation = u @ np.diag(sigma) @ u.T, u @ vt
        scale = symmetric[1, 1]
        powers = np.arange(len(self.polynomial))
        camera = ScaramuzzaCamera(self.width_px, self.height_px,
                                  tuple(np.asarray(self.polynomial) * scale ** (1.0 - powers)),
                                  self.x0_px, self.y0_px, symmetric[0, 0] / scale,
                                  symmetric[0, 1] / scale, symmetric[1, 0] / scale)
        return camera, float(np.arctan2(rotation[1, 0], rotation[0, 0]))

    def unstretch(self, pixels: np.ndarray) -> np.ndarray:
        """Distorted pixels → undistorted offsets (x' − x0, y' − y0) (Eq. 7 inverted)."""
        offsets = pixels - np.array([self.x0_px, self.y0_px])
        return offsets @ np.linalg.inv(self.stretch).T

    def pixel_to_ray(self, pixels: ArrayLike) -> np.ndarray:
        """Eqs. 6–7: distorted pixels → unit rays; NaN beyond `max_radius_px`."""
        offsets = self.unstretch(as_points(pixels, 2))
        radius = np.hypot(offsets[:, 0], offsets[:, 1])
        rays = np.column_stack([offsets, polynomial.polyval(radius, self.polynomial)])
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        rays[radius > self.max_radius_px] = np.nan
        return rays

    def project(self, points: ArrayLike) -> np.ndarray:
        """Camera-frame points → distorted pixels; NaN outside the model's field of view."""
        points = as_points(points, 3)
        lateral = np.hypot(points[:, 0], points[:, 1])
        angle = np.arctan2(lateral, points[:, 2])
        radius = self._radius_at_angle(angle)
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(lateral > 0, radius / lateral, radius)  # on the axis: r' = 0 or NaN
        offsets = points[:, :2] * scale[:, None]
        return offsets @ self.stretch.T + np.array([self.x0_px, self.y0_px])

    def _radius_at_angle(self, angle: np.ndarray) -> np.ndarray:
        """Radius r' whose ray makes `angle` [rad] with the optical axis (root of Eq. 6)."""
        radius = np.interp(angle, self._angle_table, self._radius_table)
        sin_a, cos_a = np.sin(angle), np.cos(angle)
        derivative = polynomial.polyder(self.polynomial)
        for _ in range(PROJECTION_MAX_ITERATIONS):
            # Zero when (r', P(r')) is parallel to (sin angle, cos angle); increasing in r'.
            value = radius * cos_a - polynomial.polyval(radius, self.polynomial) * sin_a
            slope = cos_a - polynomial.polyval(radius, derivative) * sin_a
            step = value / slope
            radius = np.clip(radius - step, 0.0, self.max_radius_px)
            if not np.any(np.abs(step) > PROJECTION_TOLERANCE_PX):
                break
        outside = ~((angle >= self._angle_table[0]) & (angle <= self._angle_table[-1]))
        radius[outside] = np.nan
        return radius

    def scaled(self, factor: float) -> ScaramuzzaCamera:
        """Offsets scale with the image, so a_i' = a_i factor^(1 - i); the stretch is unchanged."""
        powers = np.arange(len(self.polynomial))
        return ScaramuzzaCamera(scaled_size(self.width_px, factor),
                                scaled_size(self.height_px, factor),
                                tuple(np.asarray(self.polynomial) * factor ** (1.0 - powers)),
                                scaled_pixel(self.x0_px, factor), scaled_pixel(self.y0_px, factor),
                                self.c, self.e, self.m)

    def intrinsics(self) -> dict[str, float]:
        """a0, a2, a3, ... (Eq. 6), the centre x0_px, y0_px and the stretch c, e, m (Eq. 7)."""
        terms = {f"a{k}": float(a) for k, a in enumerate(self.polynomial) if k != 1}
        return {**terms, "x0_px": float(self.x0_px), "y0_px": float(self.y0_px),
                "c": float(self.c), "e": float(self.e), "m": float(self.m)}

    def with_intrinsics(self, changes: Mapping[str, float]) -> ScaramuzzaCamera:
        """The camera with the named intrinsics changed by the given amounts."""
        polynomial = [a + changes.get(f"a{k}", 0.0) if k != 1 else a
                      for k, a in enumerate(self.polynomial)]
        return replace(self, polynomial=tuple(polynomial),
                       x0_px=self.x0_px + changes.get("x0_px", 0.0),
                       y0_px=self.y0_px + changes.get("y0_px", 0.0),
                       c=self.c + changes.get("c", 0.0), e=self.e + changes.get("e", 0.0),
                       m=self.m + changes.get("m", 0.0))

    def parameters(self) -> dict[str, Any]:
        """Eq. 6 polynomial (ascending, a1 included) and Eq. 7 centre [px] and stretch."""
        return {"polynomial": [float(a) for a in self.polynomial],
                "centre_px": [float(self.x0_px), float(self.y0_px)],
                "stretch": {"c": float(self.c), "e": float(self.e), "m": float(self.m)}}

    @classmethod
    def from_parameters(cls, parameters: dict[str, Any], width_px: int, height_px: int,
                        pixel_origin: int) -> ScaramuzzaCamera:
        """From a camera file's `parameters` mapping; the centre shifts by `pixel_origin`."""
        x0, y0 = (float(v) - pixel_origin for v in parameters["centre_px"])
        stretch = {key: float(value) for key, value in parameters.get("stretch", {}).items()}
        unknown = set(stretch) - {"c", "e", "m"}
        if unknown:
            raise CameraModelError(f"unknown stretch terms {sorted(unknown)} (use c, e, m)")
        coefficients = tuple(float(a) for a in parameters["polynomial"])
        if coefficients[0] <= 0:
            raise CameraModelError(
                "a0 must be positive (optical axis +z); OCamCalib's negative a0 needs its importer")
        camera = cls(width_px, height_px, coefficients, x0, y0, **stretch)
        if not camera.covers_image:
            raise CameraModelError(
                f"the model is not one-to-one beyond r' = {camera.max_radius_px:.1f} px, "
                "inside the image")
        return camera
