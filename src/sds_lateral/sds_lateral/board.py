"""The lateral camera's pose in the rig's world frame, from images of its checkerboard placed
at known places (one image each; at two depths they are a 3D target)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import cv2
import numpy as np
from sds_model.camera.model import CameraModel
from sds_model.errors import InputError
from sds_model.geometry import RigidTransform
from sds_recon.calibration.board import detect_corners

from sds_lateral.view import BoardPlacement

POSE_STEP = 1e-5
"""Finite-difference step of the pose's six parameters [rad, mm] for its Jacobian."""


class BoardError(InputError):
    """No usable checkerboard in the image; the message says what was looked for."""


@dataclass(frozen=True)
class BoardPose:
    """World → camera transform (seed Eq. 1) measured from the board's corners, with what its
    σ comes from: the corners [px] and their RMS reprojection error [px], the covariance of
    the pose's rotation vector [rad] and translation [mm] from the corners' scatter, the camera
    file's intrinsics σ (the pose moves with them), the board's placement σ [mm]; and the
    resulting σ of the camera centre [mm, world] and of its rotation about the world axes
    [deg]."""

    world_to_camera: RigidTransform
    boards: tuple[BoardPlacement, ...]
    corners_px: np.ndarray            # every board's corners, in order (N×2)
    corners_mm: np.ndarray            # where they are (N×3, world)
    reprojection_rms_px: float
    covariance: np.ndarray
    camera_sigma: Mapping[str, float]
    position_sigma_mm: np.ndarray
    angle_sigma_deg: np.ndarray

    @property
    def camera_position_mm(self) -> np.ndarray:
        """The camera centre in the world frame [mm]."""
        return self.world_to_camera.inverse().translation_mm


def board_corners_px(image: np.ndarray, placement: BoardPlacement) -> np.ndarray:
    """The board's inner corners (N×2 px, `sds_recon.calibration.board.detect_corners`), in
    the order of `BoardPlacement.corners_mm`: rows to the image's right, columns down."""
    board = placement.board
    corners = detect_corners(image, board)
    if corners is None:
        raise BoardError(f"no checkerboard of {board.columns}x{board.rows} inner corners "
                         "found (the view file's inner_corners)")
    grid = corners.reshape(board.rows, board.columns, 2).astype(float)
    if np.mean(np.diff(grid[:, :, 0], axis=1)) < 0:     # rows run to the left: turn them
        grid = grid[:, ::-1]
    if np.mean(np.diff(grid[:, :, 1], axis=0)) < 0:     # columns run up: turn them
        grid = grid[::-1]
    return grid.reshape(-1, 2)


def _pose(parameters: np.ndarray) -> RigidTransform:
    return RigidTransform.from_rotation_vector(parameters[:3], parameters[3:])


def solve_pose(corners_px: np.ndarray, corners_mm: np.ndarray, camera: CameraModel
               ) -> RigidTransform:
    """World → camera from corners seen [px] at known places [mm, world] (PnP on the camera
    model's own normalised rays, so any model of the one interface works; planar or not;
    Levenberg–Marquardt refined)."""
    rays = camera.pixel_to_ray(corners_px)
    normalised = rays[:, :2] / rays[:, 2:]
    ok, rotation_vector, translation = cv2.solvePnP(corners_mm, normalised, np.eye(3), None,
                                                    flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise BoardError("the board's corners give no camera pose")
    rotation_vector, translation = cv2.solvePnPRefineLM(corners_mm, normalised, np.eye(3), None,
                                                        rotation_vector, translation)
    return _pose(np.concatenate([rotation_vector.ravel(), translation.ravel()]))


def perturbed_pose(pose: RigidTransform, change: np.ndarray) -> RigidTransform:
    """The pose with its rotation vector [rad] and translation [mm] changed by `change` (6):
    the parameters `BoardPose.covariance` is given in."""
    return _pose(np.concatenate([pose.rotation_vector(), pose.translation_mm]) + change)


def _centre_and_angles(transform: RigidTransform, reference: RigidTransform) -> np.ndarray:
    """The camera centre [mm] and its rotation from `reference` about the world axes [rad]."""
    world_rotation = transform.rotation.T @ reference.rotation   # ≈ I + [δθ]× in world axes
    angles = np.array([world_rotation[2, 1], world_rotation[0, 2], world_rotation[1, 0]])
    return np.concatenate([transform.inverse().translation_mm, angles])


def camera_pose_from_boards(images: list[np.ndarray], boards: tuple[BoardPlacement, ...],
                            camera: CameraModel,
                            camera_sigma: Mapping[str, float] | None = None) -> BoardPose:
    """The camera's pose from its images of `boards` (one each, in order), with its σ: the
    corners' scatter (Gauss–Newton covariance), each intrinsic of `camera_sigma` (the pose
    solved again with it moved by its σ), and for the centre the boards' placement σ."""
    if len(images) != len(boards):
        raise BoardError(f"{len(images)} board images for the view file's {len(boards)} board "
                         "placements (one image each, in the file's order)")
    camera_sigma = dict(camera_sigma or {})
    found = []
    for index, (image, board) in enumerate(zip(images, boards, strict=True)):
        try:
            found.append(board_corners_px(image, board))
        except BoardError as error:
            raise BoardError(f"board image {index + 1}: {error}") from None
    corners_px = np.concatenate(found)
    corners_mm = np.concatenate([board.corners_mm() for board in boards])
    pose = solve_pose(corners_px, corners_mm, camera)
    parameters = np.concatenate([pose.rotation_vector(), pose.translation_mm])

    def reprojected(values: np.ndarray) -> np.ndarray:
        return camera.project(_pose(values).apply(corners_mm)).ravel()

    steps = np.eye(6) * POSE_STEP
    residual = reprojected(parameters) - corners_px.ravel()
    jacobian = np.column_stack([(reprojected(parameters + step) - reprojected(parameters - step))
                                / (2 * POSE_STEP) for step in steps])
    dof = max(residual.size - 6, 1)
    covariance = np.linalg.inv(jacobian.T @ jacobian) * float(residual @ residual) / dof
    transfer = np.column_stack([(_centre_and_angles(perturbed_pose(pose, step), pose)
                                 - _centre_and_angles(perturbed_pose(pose, -step), pose))
                                / (2 * POSE_STEP) for step in steps])
    variance = np.diag(transfer @ covariance @ transfer.T).copy()
    for name, sigma in camera_sigma.items():
        moved = [_centre_and_angles(solve_pose(corners_px, corners_mm,
                                               camera.with_intrinsics({name: sign * sigma})),
                                    pose) for sign in (1.0, -1.0)]
        variance += ((moved[0] - moved[1]) / 2) ** 2
    spread = np.sqrt(variance)
    return BoardPose(pose, tuple(boards), corners_px, corners_mm,
                     float(np.sqrt(np.mean(residual**2) * 2)), covariance, camera_sigma,
                     np.hypot(spread[:3], placement_sigma_mm(boards)), np.degrees(spread[3:]))


def placement_sigma_mm(boards: tuple[BoardPlacement, ...]) -> float:
    """The σ the boards' placements leave on the pose's position [mm, per axis]: their RMS,
    not shrunk by their number (one holder places the board at each, and its error, a base
    0.1 mm high, is common to all)."""
    return float(np.sqrt(np.mean([b.placement_sigma_mm**2 for b in boards])))
