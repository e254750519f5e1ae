"""Camera calibration from checkerboard images: detect, fit, re-detect outlying corners, refit."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np
from sds_model.errors import InputError

from sds_recon.calibration.board import (
    BoardView,
    Checkerboard,
    detect_views,
    refine_corners,
    subpix_half_windows,
)
from sds_recon.calibration.intrinsics import Calibration, calibrate_pinhole, calibrate_scaramuzza

OUTLIER_MIN_PX = 3.0
"""A corner is an outlier when its residual exceeds this and OUTLIER_MEDIAN_FACTOR × the median."""
OUTLIER_MEDIAN_FACTOR = 8.0
REDETECTED_MAX_PX = 1.0
"""A re-detected corner is kept when it lands this close to the model's prediction [px]."""

FITS = {"pinhole": calibrate_pinhole, "scaramuzza": calibrate_scaramuzza}


@dataclass(frozen=True)
class CornerCorrection:
    """One outlying corner: re-detected at the model's prediction, or dropped."""

    image: str
    corner: int
    residual_before_px: float
    action: str  # "redetected" or "dropped"


@dataclass(frozen=True)
class CalibrationRun:
    """The calibration with its bookkeeping: images without a board, corners corrected."""

    model: str
    board: Checkerboard
    calibration: Calibration
    rejected_images: list[str]
    corrections: list[CornerCorrection] = field(default_factory=list)


def _outliers(residuals: np.ndarray, median_px: float) -> np.ndarray:
    distance = np.linalg.norm(residuals, axis=1)
    return np.flatnonzero(distance > max(OUTLIER_MIN_PX, OUTLIER_MEDIAN_FACTOR * median_px))


def correct_outliers(calibration: Calibration, images: dict[str, Path], board: Checkerboard
                     ) -> tuple[list[BoardView], list[CornerCorrection]]:
    """Re-detect outlying corners from their reprojected position; drop those that stay off."""
    median = float(np.median(np.concatenate(
        [np.linalg.norm(e.residuals_px, axis=1) for e in calibration.errors])))
    views, corrections = [], []
    for view, error, pose in zip(calibration.views, calibration.errors, calibration.poses,
                                 strict=True):
        bad = _outliers(error.residuals_px, median)
        if len(bad) == 0:
            views.append(view)
            continue
        gray = cv2.imread(str(images[view.name]), cv2.IMREAD_GRAYSCALE)
        if gray is None:
            raise InputError(f"{images[view.name]}: cannot be read again")
        predicted = calibration.camera.project(pose.apply(view.object_points[bad]))
        redetected = refine_corners(gray, predicted,
                                    subpix_half_windows(view.image_points, board)[bad])
        close = np.linalg.norm(redetected - predicted, axis=1) <= REDETECTED_MAX_PX
        image_points = view.image_points.copy()
        image_points[bad[close]] = redetected[close]
        keep = np.ones(len(image_points), dtype=bool)
        keep[bad[~close]] = False
        for index, ok in zip(bad, close, strict=True):
            corrections.append(CornerCorrection(view.name, int(index),
                                                float(np.linalg.norm(error.residuals_px[index])),
                                                "redetected" if ok else "dropped"))
        views.append(replace(view, image_points=image_points[keep],
                             object_points=view.object_points[keep]))
    return views, corrections


def calibrate_camera(paths: list[Path], board: Checkerboard, model: str) -> CalibrationRun:
    """Detect the board in every image, fit `model`, re-detect outlying corners once, refit."""
    if model not in FITS:
        raise InputError(f"model must be one of {sorted(FITS)}, got {model!r}")
    views, rejected, (width, height) = detect_views(paths, board)
    calibration = FITS[model](views, width, height)
    views, corrections = correct_outliers(calibration, {p.name: p for p in paths}, board)
    if corrections:
        calibration = FITS[model](views, width, height)
    return CalibrationRun(model, board, calibration, rejected, corrections)
