"""Checkerboard targets and sub-pixel corner detection for intrinsic calibration."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from sds_model.errors import InputError

SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 30, 0.1)
"""cornerSubPix stop rule of OpenCV's own calibration regression test."""
SUBPIX_HALF_WINDOW_PX = 5
"""Largest cornerSubPix half window: 11×11 px, as in OpenCV's calibration regression test."""


@dataclass(frozen=True)
class Checkerboard:
    """A planar checkerboard: inner corners per row (columns) and per column (rows), square [mm]."""

    columns: int
    rows: int
    square_mm: float

    @classmethod
    def parse(cls, size: str, square_mm: float) -> Checkerboard:
        """From 'COLSxROWS' (inner corners, e.g. '9x6') and the square size [mm]."""
        try:
            columns, rows = (int(v) for v in size.lower().split("x"))
        except ValueError as error:
            raise InputError(f"board size must look like 9x6 (inner corners): {size!r}") from error
        if columns < 2 or rows < 2 or square_mm <= 0:
            raise InputError(f"need 2x2 inner corners or more, square > 0: {size}, {square_mm}")
        return cls(columns, rows, float(square_mm))

    @property
    def pattern_size(self) -> tuple[int, int]:
        """OpenCV's patternSize (corners per row, corners per column)."""
        return self.columns, self.rows

    def object_points(self) -> np.ndarray:
        """Corner positions on the board plane (Z = 0) [mm], in OpenCV's detection order."""
        grid = np.indices((self.columns, self.rows)).T.reshape(-1, 2).astype(float)
        return np.column_stack([grid * self.square_mm, np.zeros(len(grid))])


@dataclass(frozen=True)
class BoardView:
    """One image of a board: its name, detected corners (N×2 px) and board points (N×3 mm)."""

    name: str
    image_points: np.ndarray
    object_points: np.ndarray


def detect_corners(image: np.ndarray, board: Checkerboard) -> np.ndarray | None:
    """Inner corners (N×2, x = column, y = row) refined to sub-pixel, or None if not all found.

    OpenCV's classic detector first (the one its regression numbers use), refined by
    cornerSubPix; the sector-based detector when that fails (stronger on fisheye images),
    whose corners are already sub-pixel.
    """
    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    found, corners = cv2.findChessboardCorners(
        gray, board.pattern_size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
    if found:
        corners = corners.reshape(-1, 2)
        return refine_corners(gray, corners, subpix_half_windows(corners, board))
    found, corners = cv2.findChessboardCornersSB(
        gray, board.pattern_size, flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
    return corners.reshape(-1, 2).astype(float) if found else None


def subpix_half_windows(corners: np.ndarray, board: Checkerboard) -> np.ndarray:
    """Per corner: the largest cornerSubPix half window (2–5 px) under 40 % of the distance to
    its nearest grid neighbour, so that the window never reaches the next corner."""
    grid = corners.reshape(board.rows, board.columns, 2)
    nearest = np.full(grid.shape[:2], np.inf)
    for axis in (0, 1):
        step = np.linalg.norm(np.diff(grid, axis=axis), axis=2)
        before = [slice(None)] * 2
        after = [slice(None)] * 2
        before[axis], after[axis] = slice(1, None), slice(None, -1)
        nearest[tuple(before)] = np.minimum(nearest[tuple(before)], step)
        nearest[tuple(after)] = np.minimum(nearest[tuple(after)], step)
    return np.clip(np.floor(0.4 * nearest.ravel()), 2, SUBPIX_HALF_WINDOW_PX).astype(int)


def refine_corners(gray: np.ndarray, corners: np.ndarray, half_windows: np.ndarray) -> np.ndarray:
    """cornerSubPix with OpenCV's regression-test stop rule, one half window per corner [px]."""
    refined = corners.astype(np.float32).reshape(-1, 1, 2).copy()
    for half in np.unique(half_windows):
        chosen = half_windows == half
        group = refined[chosen].copy()
        cv2.cornerSubPix(gray, group, (int(half), int(half)), (-1, -1), SUBPIX_CRITERIA)
        refined[chosen] = group
    return refined.reshape(-1, 2).astype(float)


def detect_views(paths: list[Path], board: Checkerboard
                 ) -> tuple[list[BoardView], list[str], tuple[int, int]]:
    """Board views of the images where every corner was found, the names of the others, and
    the image size (width, height) [px], which every image must share."""
    views: list[BoardView] = []
    rejected: list[str] = []
    size: tuple[int, int] | None = None
    for path in paths:
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise InputError(f"cannot read image {path}")
        this_size = (image.shape[1], image.shape[0])
        if size is not None and this_size != size:
            raise InputError(f"{path} is {this_size} px (width, height), the others {size}")
        size = this_size
        corners = detect_corners(image, board)
        if corners is None:
            rejected.append(path.name)
        else:
            views.append(BoardView(path.name, corners, board.object_points()))
    if size is None:
        raise InputError("no images given")
    return views, rejected, size
