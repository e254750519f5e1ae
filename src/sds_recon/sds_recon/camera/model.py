"""The one camera-model interface and the camera file (YAML) loader and writer."""

from __future__ import annotations

import textwrap
from abc import ABC, abstractmethod
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import yaml
from numpy.typing import ArrayLike

FILE_HEADER = """\
# SDS camera model (load with sds_recon.camera.load_camera).
# Conventions: pixel x = column, y = row, full frame, the centre of the top-left pixel at
# (0, 0) unless pixel_origin says 1 (MATLAB's convention; the loader subtracts 1 from centres).
# Camera frame: x to the right (columns), y down (rows), z along the optical axis into the scene.
"""


class CameraModelError(ValueError):
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


def _model_classes() -> dict[str, type[CameraModel]]:
    from sds_recon.camera.pinhole import PinholeCamera
    from sds_recon.camera.scaramuzza import ScaramuzzaCamera

    return {cls.model_name: cls for cls in (PinholeCamera, ScaramuzzaCamera)}


def camera_from_dict(content: dict[str, Any]) -> CameraModel:
    """Build a camera model from the mapping of a camera file."""
    if not isinstance(content, dict):
        raise CameraModelError("a camera file must be a YAML mapping")
    classes = _model_classes()
    name = content.get("model")
    if name not in classes:
        raise CameraModelError(f"model must be one of {sorted(classes)}, got {name!r}")
    try:
        width, height = (int(v) for v in content["image_size"])
        origin = int(content.get("pixel_origin", 0))
        parameters = content["parameters"]
    except KeyError as error:
        raise CameraModelError(f"camera file lacks {error.args[0]!r}") from error
    except (TypeError, ValueError) as error:
        raise CameraModelError(f"image_size must be [width, height] in px: {error}") from error
    if origin not in (0, 1):
        raise CameraModelError(f"pixel_origin must be 0 or 1, got {origin}")
    if width <= 0 or height <= 0:
        raise CameraModelError(f"image_size must be positive, got {width}×{height}")
    try:
        return classes[name].from_parameters(dict(parameters), width, height, origin)
    except CameraModelError:
        raise
    except (KeyError, TypeError, ValueError) as error:
        raise CameraModelError(f"bad {name} parameters: {error!r}") from error


def read_yaml(path: str | Path) -> Any:
    """The content of a YAML (or JSON) file; CameraModelError if it cannot be read or parsed."""
    try:
        return yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as error:
        raise CameraModelError(f"cannot read {path}: {error}") from error


def load_camera(path: str | Path) -> CameraModel:
    """Read a camera file (config/cameras/*.yaml)."""
    content = read_yaml(path)
    try:
        return camera_from_dict(content)
    except CameraModelError as error:
        raise CameraModelError(f"{path}: {error}") from error


def camera_to_yaml(camera: CameraModel, comment: str = "") -> str:
    """The camera file text, with the conventions header and an optional comment."""
    lines = [FILE_HEADER]
    lines += [f"# {line}" for line in textwrap.wrap(comment, width=96)]
    body = yaml.safe_dump(camera.to_dict(), sort_keys=False, default_flow_style=None, width=100)
    return "\n".join(lines) + ("\n" if comment else "") + body


def save_camera(camera: CameraModel, path: str | Path, comment: str = "") -> Path:
    """Write a camera file that load_camera reads back to the same model."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(camera_to_yaml(camera, comment))
    return path
