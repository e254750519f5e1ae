"""`sds calibrate line-plane`: a camera and the line laser's plane from images of a checkerboard
crossed by the line (seed Sec. 3.3.1 with a board as the known surface).

Calibrates the camera on the board (sds_recon.calibration.camera_calibration), finds the line's
centre per row inside each board's corner hull (sds_tracker.line.find_line on the image's
redness), puts those pixels on the board plane of that view and fits one plane to all of them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from sds_model.errors import InputError
from sds_recon.calibration.board import Checkerboard
from sds_recon.calibration.camera_calibration import CalibrationRun, calibrate_camera
from sds_recon.calibration.lasers import (
    PlaneFitResult,
    board_points,
    calibrate_line_plane_on_boards,
)
from sds_tracker.line import LineSettings, find_line, redness

HULL_INSET_PX = 3.0
"""Line pixels closer than this to the corner hull's edge are left out (the band reaches out)."""
LINE_BAND_PX = 15
"""Columns searched on each side of a row's seed centre (1152 px wide images: about 3 widths)."""


@dataclass(frozen=True)
class LinePlaneCalibration:
    """The camera run, the plane (camera frame), and per view its line pixel count [px]."""

    camera_run: CalibrationRun
    plane: PlaneFitResult
    line_pixels: dict[str, np.ndarray]

    def residuals_mm(self) -> np.ndarray:
        """Signed distance of every line point from the fitted plane [mm]."""
        points = [board_points(self.camera_run.calibration.camera, pose, self.line_pixels[v.name])
                  for pose, v in zip(self.camera_run.calibration.poses,
                                     self.camera_run.calibration.views, strict=True)]
        stacked = np.vstack(points)
        return (stacked[np.isfinite(stacked).all(axis=1)] - self.plane.point_mm) @ \
            self.plane.normal


def line_on_board(image: np.ndarray, corners_px: np.ndarray) -> np.ndarray:
    """The line's centres (N×2 px) inside the hull of a board's detected corners."""
    hull = cv2.convexHull(corners_px.astype(np.float32))
    mask = np.zeros(image.shape[:2], np.uint8)
    cv2.fillConvexPoly(mask, hull.astype(np.int32), 1)
    profile = find_line(redness(image), mask, LineSettings(band_px=LINE_BAND_PX))
    pixels = np.column_stack([profile.x_px, profile.y_px])
    inside = [cv2.pointPolygonTest(hull, (float(x), float(y)), True) > HULL_INSET_PX
              for x, y in pixels]
    return pixels[np.array(inside, dtype=bool)].reshape(-1, 2)


def calibrate_line_plane(images: list[Path], board: Checkerboard, model: str = "pinhole"
                         ) -> LinePlaneCalibration:
    """Camera and line plane from colour images of a board the line crosses (one pose each)."""
    run = calibrate_camera(images, board, model)
    by_name = {path.name: path for path in images}
    line_pixels = {}
    for view in run.calibration.views:
        image = cv2.imread(str(by_name[view.name]), cv2.IMREAD_COLOR)
        if image is None:
            raise InputError(f"{by_name[view.name]}: not a readable image")
        line_pixels[view.name] = line_on_board(image, view.image_points)
    plane = calibrate_line_plane_on_boards(
        run.calibration.camera, run.calibration.poses,
        [line_pixels[v.name] for v in run.calibration.views])
    return LinePlaneCalibration(run, plane, line_pixels)


def line_plane_report(result: LinePlaneCalibration) -> dict[str, object]:
    """The plane (n·X + d = 0, camera frame, mm), its residuals and the camera, as plain data."""
    residuals = result.residuals_mm()
    normal = result.plane.normal
    return {
        "plane_n_d": [*normal.tolist(), float(-normal @ result.plane.point_mm)],
        "equation": "n . X + d = 0, X in the camera frame [mm], |n| = 1",
        "points": len(residuals),
        "residual_mean_abs_mm": float(np.mean(np.abs(residuals))),
        "residual_rms_mm": float(np.sqrt(np.mean(residuals**2))),
        "residual_max_abs_mm": float(np.max(np.abs(residuals))),
        "line_pixels_per_image": {k: len(v) for k, v in result.line_pixels.items()},
        "images_without_board": result.camera_run.rejected_images,
        "camera_rms_px": result.camera_run.calibration.rms_px,
        "camera": result.camera_run.calibration.camera.to_dict(),
    }
