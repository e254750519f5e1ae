"""Rigid transforms between world, rig and camera frames (seed Eq. 1)."""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import ArrayLike

_IDENTITY = np.eye(3)
_ORTHONORMAL_TOLERANCE = 1e-9 + 1e-5 * _IDENTITY
"""How far R Rᵀ may be from the identity, entry by entry: np.allclose's atol 1e-9 and
rtol 1e-5, the check this replaces."""


def _determinant(matrix: np.ndarray) -> float:
    """The determinant of a 3×3 matrix (the triple product of its rows)."""
    (a, b, c), (d, e, f), (g, h, i) = matrix.tolist()
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)


@dataclass(frozen=True)
class RigidTransform:
    """P_C = R P_W + t (seed Eq. 1); rotation 3×3, translation in mm."""

    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    translation_mm: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        rotation = np.asarray(self.rotation, dtype=float).reshape(3, 3)
        translation = np.asarray(self.translation_mm, dtype=float).reshape(3)
        # Cheap checks (not np.allclose, np.linalg.det): fits build a transform per pose per
        # evaluation.
        error = np.abs(rotation @ rotation.T - _IDENTITY)
        orthonormal = bool(np.all(error <= _ORTHONORMAL_TOLERANCE))
        if not orthonormal or _determinant(rotation) < 0:
            raise ValueError("rotation must be a proper orthonormal 3×3 matrix")
        object.__setattr__(self, "rotation", rotation)
        object.__setattr__(self, "translation_mm", translation)

    @classmethod
    def from_rotation_vector(cls, rotation_vector: ArrayLike,
                             translation_mm: ArrayLike) -> RigidTransform:
        """Transform from an axis-angle vector [rad] (OpenCV's Rodrigues convention)."""
        rotation, _ = cv2.Rodrigues(np.asarray(rotation_vector, dtype=float).reshape(3, 1))
        return cls(rotation, np.asarray(translation_mm, dtype=float))

    def rotation_vector(self) -> np.ndarray:
        """The rotation as an axis-angle vector [rad]."""
        vector, _ = cv2.Rodrigues(self.rotation)
        return vector.reshape(3)

    def apply(self, points: ArrayLike) -> np.ndarray:
        """Map N×3 points from the source frame to the target frame [mm]."""
        return np.asarray(points, dtype=float) @ self.rotation.T + self.translation_mm

    def inverse(self) -> RigidTransform:
        """The transform from the target frame back to the source frame."""
        return RigidTransform(self.rotation.T, -self.rotation.T @ self.translation_mm)

    def compose(self, first: RigidTransform) -> RigidTransform:
        """The transform that applies `first`, then this one."""
        return RigidTransform(self.rotation @ first.rotation,
                              self.rotation @ first.translation_mm + self.translation_mm)


def ray_plane_points(origin: np.ndarray, rays: np.ndarray, normal: np.ndarray,
                     offset: float | np.ndarray) -> np.ndarray:
    """Where rays (N×3) from `origin` (3, or one per ray N×3) meet the plane normal · X =
    offset (one plane, or one per ray: normals N×3, offsets N) (N×3, the rays' units); NaN for
    rays that meet it behind the origin or never. Every ray–plane intersection of the
    project is this one."""
    with np.errstate(divide="ignore", invalid="ignore"):
        distance = np.asarray((offset - np.sum(origin * normal, axis=-1))
                              / np.sum(rays * normal, axis=-1), dtype=float).reshape(-1)
    distance[~(distance > 0)] = np.nan
    return origin + distance[:, None] * rays
