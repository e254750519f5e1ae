"""Camera files (YAML): the model registry, the loader and the writer."""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

import yaml

from sds_model.camera.model import CameraModel, CameraModelError
from sds_model.camera.pinhole import PinholeCamera
from sds_model.camera.scaramuzza import ScaramuzzaCamera

FILE_HEADER = """\
# SDS camera model (load with sds_model.camera.load_camera).
# Conventions: pixel x = column, y = row, full frame, the centre of the top-left pixel at
# (0, 0) unless pixel_origin says 1 (MATLAB's convention; the loader subtracts 1 from centres).
# Camera frame: x to the right (columns), y down (rows), z along the optical axis into the scene.
"""

MODELS: dict[str, type[CameraModel]] = {
    cls.model_name: cls for cls in (PinholeCamera, ScaramuzzaCamera)}
"""Every camera model a camera file may name (its `model` key), by name."""


def camera_from_dict(content: dict[str, Any]) -> CameraModel:
    """Build a camera model from the mapping of a camera file."""
    if not isinstance(content, dict):
        raise CameraModelError("a camera file must be a YAML mapping")
    name = content.get("model")
    if name not in MODELS:
        raise CameraModelError(f"model must be one of {sorted(MODELS)}, got {name!r}")
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
        return MODELS[name].from_parameters(dict(parameters), width, height, origin)
    except CameraModelError:
        raise
    except (KeyError, TypeError, ValueError) as error:
        raise CameraModelError(f"bad {name} parameters: {error!r}") from error


def camera_sigma(content: dict[str, Any], camera: CameraModel) -> dict[str, float]:
    """The one-sigma errors of a camera file's calibration (`sigma:`, a mapping from the
    model's intrinsic names to σ in their units; absent: none declared)."""
    sigma = content.get("sigma") or {}
    if not isinstance(sigma, dict):
        raise CameraModelError("sigma must be a mapping of intrinsic names to one-sigma errors")
    known = camera.intrinsics()
    unknown = sorted(set(sigma) - set(known))
    if unknown:
        raise CameraModelError(f"sigma: unknown intrinsics {unknown} (known: {sorted(known)})")
    try:
        values = {str(name): float(value) for name, value in sigma.items()}
    except (TypeError, ValueError) as error:
        raise CameraModelError(f"sigma: each value must be a number: {error}") from error
    if any(not value >= 0 for value in values.values()):
        raise CameraModelError("sigma: every one-sigma error must be zero or positive")
    return {name: value for name, value in values.items() if value > 0}


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
