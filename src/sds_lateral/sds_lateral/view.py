"""The lateral view file: the side camera's model, frame rate, LED region and checkerboards."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from sds_model.camera.files import camera_from_dict, camera_sigma, read_yaml
from sds_model.camera.model import CameraModel, CameraModelError
from sds_model.errors import InputError
from sds_recon.calibration.board import Checkerboard

VIEW_KEYS = ("camera", "fps", "led_roi_px", "boards")
BOARD_KEYS = ("inner_corners", "square_mm", "first_corner_mm", "row_direction",
              "column_direction", "placement_sigma_mm")


class LateralViewError(InputError):
    """A lateral view file that does not describe a usable side view; names file and field."""


@dataclass(frozen=True)
class BoardPlacement:
    """A checkerboard (`sds_recon.calibration.board.Checkerboard`) placed in the rig's world
    frame: the inner corner at the image's top left [mm, world], the unit directions along a
    row and down a column of corners, and how well its holder places it [mm, σ per axis]."""

    board: Checkerboard
    first_corner_mm: np.ndarray
    row_direction: np.ndarray
    column_direction: np.ndarray
    placement_sigma_mm: float = 0.0

    def corners_mm(self) -> np.ndarray:
        """The inner corners in world coordinates [mm], in OpenCV's detection order (row by
        row from the top left, each row left to right): (columns · rows)×3."""
        on_board = self.board.object_points()
        return (self.first_corner_mm + on_board[:, :1] * self.row_direction
                + on_board[:, 1:2] * self.column_direction)

    @property
    def normal(self) -> np.ndarray:
        """The board's unit normal (row × column direction)."""
        normal = np.cross(self.row_direction, self.column_direction)
        return normal / np.linalg.norm(normal)


@dataclass(frozen=True)
class LateralView:
    """The side camera: its model (with its file's σ), frame rate [Hz], the sync LED's region
    (x, y, width, height [px]) and the checkerboard placements that place it (one image each;
    two at different depths make a 3D target, which a camera file's focal lengths cannot
    bend)."""

    camera: CameraModel
    camera_file: Path
    camera_sigma: dict[str, float]
    fps: float
    led_roi_px: tuple[int, int, int, int]
    boards: tuple[BoardPlacement, ...]


def _vector(section: dict[str, Any], key: str, where: str, length: int = 3) -> np.ndarray:
    value = section.get(key)
    try:
        vector = np.asarray(value, dtype=float).reshape(length)
    except (TypeError, ValueError):
        raise LateralViewError(f"{where}.{key} must be {length} numbers, got {value!r}") from None
    if not np.all(np.isfinite(vector)):
        raise LateralViewError(f"{where}.{key} must be finite, got {value!r}")
    return vector


def _unknown(section: dict[str, Any], allowed: tuple[str, ...], where: str) -> None:
    unknown = sorted(set(section) - set(allowed))
    if unknown:
        raise LateralViewError(f"{where}: unknown keys {unknown} (known: {list(allowed)})")


def _board(section: Any, where: str) -> BoardPlacement:
    if not isinstance(section, dict):
        raise LateralViewError(f"{where} must be a mapping (a checkerboard's placement)")
    _unknown(section, BOARD_KEYS, where)
    corners = _vector(section, "inner_corners", where, 2)
    if np.any(corners < 2) or np.any(corners != np.round(corners)):
        raise LateralViewError(f"{where}.inner_corners must be two whole numbers of 2 or "
                               f"more, got {section.get('inner_corners')!r}")
    square = float(section.get("square_mm", 0.0))
    if not square > 0:
        raise LateralViewError(f"{where}.square_mm must be positive, got {square}")
    row, column = (_vector(section, key, where) for key in ("row_direction",
                                                            "column_direction"))
    row, column = row / np.linalg.norm(row), column / np.linalg.norm(column)
    if abs(float(row @ column)) > 1e-6:
        raise LateralViewError(f"{where}.row_direction and column_direction must be "
                               "perpendicular")
    return BoardPlacement(Checkerboard(int(corners[0]), int(corners[1]), square),
                          _vector(section, "first_corner_mm", where), row, column,
                          float(section.get("placement_sigma_mm", 0.0)))


def _boards(section: Any) -> tuple[BoardPlacement, ...]:
    if not isinstance(section, list) or not section:
        raise LateralViewError("boards must be a list of checkerboard placements (one image "
                               "of the board at each)")
    return tuple(_board(entry, f"boards[{index}]") for index, entry in enumerate(section))


def load_lateral_view(path: str | Path) -> LateralView:
    """Read and check a lateral view file (config/lateral/*.yaml); its camera file is taken
    relative to it."""
    path = Path(path)
    try:
        content = read_yaml(path)
        if not isinstance(content, dict):
            raise LateralViewError("a lateral view file must be a YAML mapping")
        _unknown(content, VIEW_KEYS, "the view")
        if "camera" not in content:
            raise LateralViewError("camera is missing (a camera file, config/cameras/*.yaml)")
        camera_file = (path.parent / str(content["camera"])).resolve()
        camera_content = read_yaml(camera_file)
        camera = camera_from_dict(camera_content)
        fps = float(content.get("fps", 0.0))
        if not fps > 0:
            raise LateralViewError(f"fps must be positive, got {content.get('fps')!r}")
        roi = _vector(content, "led_roi_px", "the view", 4)
        if np.any(roi[2:] < 1) or roi[0] < 0 or roi[1] < 0 or \
                roi[0] + roi[2] > camera.width_px or roi[1] + roi[3] > camera.height_px:
            raise LateralViewError(f"led_roi_px {content['led_roi_px']} must lie inside the "
                                   f"{camera.width_px}x{camera.height_px} image")
        return LateralView(camera, camera_file, camera_sigma(camera_content, camera), fps,
                           (int(roi[0]), int(roi[1]), int(roi[2]), int(roi[3])),
                           _boards(content.get("boards")))
    except (LateralViewError, CameraModelError) as error:
        raise LateralViewError(f"{path}: {error}") from error
