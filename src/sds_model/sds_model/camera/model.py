"""The one camera-model interface: pixels ↔ rays, image size, parameters as a mapping."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from sds_model.errors import InputError


class CameraModelError(InputError):
    """A camera file or parameter set that does not describe a usable camera."""


class CameraModel(ABC):
    """Maps camera-frame points to pixels and pixels to unit rays (x = column, y = row)."""

    model_name: ClassVar[str]
    width_px: int
    height_px: int

    @abstractmethod
    def project(self, points: ArrayLike) -> np.ndarray:
        """N×3 camera-frame points [any unit] → N×2 pixels; NaN where the model sees no image."""

    @abstractmethod
    def pixel_to_ray(self, pixels: ArrayLike) -> np.ndarray:
        """N×2 pixels → N×3 unit rays in the camera frame; NaN where the model is not valid."""

    @abstractmethod
    def scaled(self, factor: float) -> CameraModel:
        """The same camera with its image resampled by `factor` (0.25: a 4K sensor at 960×540)."""

    @abstractmethod
    def parameters(self) -> dict[str, Any]:
        """The model's parameters as plain YAML-ready values (pixel origin 0)."""

    @classmethod
    @abstractmethod
    def from_parameters(cls, parameters: dict[str, Any], width_px: int, height_px: int,
                        pixel_origin: int) -> CameraModel:
        """Build the model from the `parameters` mapping of a camera file."""

    @abstractmethod
    def intrinsics(self) -> dict[str, float]:
        """The model's scalar intrinsic parameters by name (the names a camera file's `sigma:`
        gives one-sigma errors for)."""

    @abstractmethod
    def with_intrinsics(self, changes: Mapping[str, float]) -> CameraModel:
        """The same camera with the named intrinsics changed by the given amounts."""

    def to_dict(self) -> dict[str, Any]:
        """The camera file content as a mapping."""
        return {"model": self.model_name, "image_size": [self.width_px, self.height_px],
                "pixel_origin": 0, "parameters": self.parameters()}

    def image_grid(self, step_px: float) -> np.ndarray:
        """Pixel centres on a regular grid over the whole image (N×2), corners included."""
        xs = np.unique(np.append(np.arange(0.0, self.width_px - 1, step_px), self.width_px - 1))
        ys = np.unique(np.append(np.arange(0.0, self.height_px - 1, step_px), self.height_px - 1))
        grid = np.stack(np.meshgrid(xs, ys), axis=-1)
        return grid.reshape(-1, 2)


def scaled_pixel(value_px: float, factor: float) -> float:
    """A pixel coordinate after resampling by `factor` (pixel centres at integers)."""
    return (value_px + 0.5) * factor - 0.5


def scaled_size(size_px: int, factor: float) -> int:
    """An image dimension after resampling by `factor`."""
    return max(1, round(size_px * factor))


def as_points(values: ArrayLike, columns: int) -> np.ndarray:
    """A float N×columns array from any array-like of points (one point may be 1-D)."""
    array = np.asarray(values, dtype=float)
    if array.ndim == 1:
        array = array.reshape(1, -1)
    if array.ndim != 2 or array.shape[1] != columns:
        raise ValueError(f"expected N×{columns} points, got shape {np.shape(values)}")
    return array
