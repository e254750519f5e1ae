"""Intrinsic calibration from checkerboard views: pinhole (OpenCV) and Scaramuzza (own fit)."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix
from sds_model.camera.model import CameraModel
from sds_model.camera.pinhole import PinholeCamera
from sds_model.camera.scaramuzza import ScaramuzzaCamera
from sds_model.errors import InputError
from sds_model.geometry import RigidTransform

from sds_recon.calibration.board import BoardView

FAILED_PROJECTION_PX = 1e3
"""Residual given to a corner the model cannot project during the fit (outside its field)."""
SCARAMUZZA_DEGREE = 4


@dataclass(frozen=True)
class ViewError:
    """Reprojection error of one view [px]: Euclidean distance per corner."""

    name: str
    residuals_px: np.ndarray

    @property
    def mean_px(self) -> float:
        """Mean distance between detected and reprojected corners [px]."""
        return float(np.mean(np.linalg.norm(self.residuals_px, axis=1)))

    @property
    def rms_px(self) -> float:
        """Root mean square of those distances [px] (OpenCV's `rms` per view)."""
        return float(np.sqrt(np.mean(np.sum(self.residuals_px**2, axis=1))))


@dataclass(frozen=True)
class Calibration:
    """A fitted camera, the board pose of every view (board → camera) and the residuals."""

    camera: CameraModel
    poses: list[RigidTransform]
    views: list[BoardView]
    errors: list[ViewError]
    converged: bool = True     # False: the fit stopped at its evaluation limit

    @property
    def mean_px(self) -> float:
        """Mean corner distance over all views [px]."""
        distances = [np.linalg.norm(e.residuals_px, axis=1) for e in self.errors]
        return float(np.mean(np.concatenate(distances)))

    @property
    def rms_px(self) -> float:
        """RMS corner distance over all views [px]."""
        squared = np.concatenate([np.sum(e.residuals_px**2, axis=1) for e in self.errors])
        return float(np.sqrt(np.mean(squared)))


def reprojection_errors(camera: CameraModel, poses: list[RigidTransform],
                        views: list[BoardView]) -> list[ViewError]:
    """Reprojected minus detected corners of every view [px]."""
    return [ViewError(view.name, camera.project(pose.apply(view.object_points)) - view.image_points)
            for pose, view in zip(poses, views, strict=True)]


def calibrate_pinhole(views: list[BoardView], width_px: int, height_px: int) -> Calibration:
    """OpenCV's calibrateCamera (k1, k2, p1, p2, k3; no skew), errors recomputed by our model."""
    if len(views) < 3:
        raise InputError(f"need at least 3 board views, got {len(views)}")
    object_points = [v.object_points.astype(np.float32) for v in views]
    image_points = [v.image_points.astype(np.float32).reshape(-1, 1, 2) for v in views]
    _, k, dist, rvecs, tvecs = cv2.calibrateCamera(object_points, image_points,
                                                   (width_px, height_px), None, None, flags=0)
    camera = PinholeCamera.from_opencv(k, dist, width_px, height_px)
    poses = [RigidTransform.from_rotation_vector(r, t) for r, t in zip(rvecs, tvecs, strict=True)]
    return Calibration(camera, poses, views, reprojection_errors(camera, poses, views))


def _linear_pose_candidates(offsets: np.ndarray, board_xy: np.ndarray) -> list[np.ndarray]:
    """Scaramuzza's first linear step: [r1 r2 t1 t2] of one view, two candidates (r31/r32 sign).

    From (u, v) × (Xc, Yc, Zc) = 0, the third component v Xc − u Yc = 0 is linear in
    r11, r12, r21, r22, t1, t2; orthonormality of r1, r2 gives r31, r32 and the scale.
    """
    u, v = offsets[:, 0], offsets[:, 1]
    x, y = board_xy[:, 0], board_xy[:, 1]
    system = np.column_stack([v * x, v * y, -u * x, -u * y, v, -u])
    h = np.linalg.svd(system)[2][-1]
    r11, r12, r21, r22, t1, t2 = h
    if np.sum(u * (r11 * x + r12 * y + t1) + v * (r21 * x + r22 * y + t2)) < 0:
        r11, r12, r21, r22, t1, t2 = -h
    a = r11 * r12 + r21 * r22
    b = r11**2 + r21**2
    c = r12**2 + r22**2
    r32_sq = (-(c - b) + np.sqrt((c - b) ** 2 + 4 * a**2)) / 2
    r31_abs, r32_abs = np.sqrt(max(r32_sq + c - b, 0.0)), np.sqrt(max(r32_sq, 0.0))
    product_sign = -1.0 if a > 0 else 1.0
    candidates = []
    for sign in (1.0, -1.0):
        r31, r32 = sign * r31_abs, sign * product_sign * r32_abs
        scale = 1.0 / np.sqrt(b + r31**2)
        candidates.append(scale * np.array([r11, r12, r21, r22, r31, r32, t1, t2]))
    return candidates


def _linear_intrinsics(offsets: list[np.ndarray], boards: list[np.ndarray], poses: list[np.ndarray],
                       radius_scale: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Scaramuzza's second linear step: polynomial (a1 = 0) and every t3, least squares.

    Returns the ascending polynomial, the t3 of each view and the algebraic residual norm.
    """
    powers = [0, *range(2, SCARAMUZZA_DEGREE + 1)]
    rows, rhs = [], []
    for index, (uv, board, pose) in enumerate(zip(offsets, boards, poses, strict=True)):
        r11, r12, r21, r22, r31, r32, t1, t2 = pose
        x, y = board[:, 0], board[:, 1]
        xc, yc, zc = r11 * x + r12 * y + t1, r21 * x + r22 * y + t2, r31 * x + r32 * y
        radius = np.hypot(uv[:, 0], uv[:, 1]) / radius_scale
        basis = np.column_stack([radius**p for p in powers])
        t3 = np.zeros((len(uv), len(poses)))
        t3_v, t3_u = t3.copy(), t3.copy()
        t3_v[:, index], t3_u[:, index] = uv[:, 1], uv[:, 0]
        rows += [np.hstack([-yc[:, None] * basis, t3_v]), np.hstack([-xc[:, None] * basis, t3_u])]
        rhs += [-uv[:, 1] * zc, -uv[:, 0] * zc]
    matrix, vector = np.vstack(rows), np.concatenate(rhs)
    solution, *_ = np.linalg.lstsq(matrix, vector, rcond=None)
    residual = float(np.linalg.norm(matrix @ solution - vector))
    scaled = solution[: len(powers)]
    polynomial = np.zeros(SCARAMUZZA_DEGREE + 1)
    polynomial[powers] = scaled / radius_scale ** np.array(powers)
    return polynomial, solution[len(powers):], residual


def _initial_scaramuzza(views: list[BoardView], centre: np.ndarray,
                        radius_scale: float) -> tuple[np.ndarray, list[RigidTransform]]:
    """Linear initial guess (Scaramuzza 2006) for a given centre, no stretch."""
    offsets = [v.image_points - centre for v in views]
    boards = [v.object_points[:, :2] for v in views]
    candidates = [_linear_pose_candidates(uv, b) for uv, b in zip(offsets, boards, strict=True)]
    choice = [0] * len(views)
    for index in range(len(views)):  # each view's sign alone, against the shared polynomial
        trials = [_linear_intrinsics([offsets[index]], [boards[index]], [candidates[index][k]],
                                     radius_scale)[2] for k in (0, 1)]
        choice[index] = int(np.argmin(trials))
    chosen = [c[k] for c, k in zip(candidates, choice, strict=True)]
    best = _linear_intrinsics(offsets, boards, chosen, radius_scale)[2]
    improved = True
    while improved:  # flip any view whose other sign fits the common polynomial better
        improved = False
        for index in range(len(views)):
            trial = choice.copy()
            trial[index] = 1 - trial[index]
            residual = _linear_intrinsics(offsets, boards,
                                          [c[k] for c, k in zip(candidates, trial, strict=True)],
                                          radius_scale)[2]
            if residual < best:
                best, choice, improved = residual, trial, True
    chosen = [c[k] for c, k in zip(candidates, choice, strict=True)]
    polynomial, t3, _ = _linear_intrinsics(offsets, boards, chosen, radius_scale)
    if polynomial[0] < 0:  # the whole solution mirrored through the centre: flip it back
        polynomial = -polynomial
        t3 = -t3
        chosen = [p * np.array([1, 1, 1, 1, -1, -1, 1, 1]) for p in chosen]
    poses = []
    for pose, t3_view in zip(chosen, t3, strict=True):
        r11, r12, r21, r22, r31, r32, t1, t2 = pose
        r1, r2 = np.array([r11, r21, r31]), np.array([r12, r22, r32])
        rotation = np.column_stack([r1, r2, np.cross(r1, r2)])
        u, _, vt = np.linalg.svd(rotation)
        poses.append(RigidTransform(u @ vt, np.array([t1, t2, t3_view])))
    return polynomial, poses


FIT_MAX_EVALUATIONS = 200
"""The Scaramuzza fit's limit of evaluations (each a finite-difference Jacobian); stopping
there, it reports itself not converged."""
INTRINSIC_COUNT = 4 + SCARAMUZZA_DEGREE
"""x0, y0, c, e (= m), a0, a2 … a_degree."""


def _scaramuzza_from_vector(vector: np.ndarray, width_px: int, height_px: int,
                            radius_scale: float) -> ScaramuzzaCamera:
    x0, y0, c, e, b0, *b = vector[:INTRINSIC_COUNT]
    powers = np.arange(2, SCARAMUZZA_DEGREE + 1)
    polynomial = (b0, 0.0, *(np.asarray(b) / radius_scale ** (powers - 1)))
    return ScaramuzzaCamera(width_px, height_px, polynomial, x0, y0, c, e, e)


def calibrate_scaramuzza(views: list[BoardView], width_px: int, height_px: int) -> Calibration:
    """Own Scaramuzza fit: linear initialisation, then least squares on every intrinsic
    (centre, stretch, a0 a2 a3 a4) and every board pose, on pixel reprojection error.

    The stretch is fitted symmetric (e = m): its rotational part equals a roll of every board
    pose, so c, e, m together are not observable (see ScaramuzzaCamera.with_symmetric_stretch).
    """
    if len(views) < 3:
        raise InputError(f"need at least 3 board views, got {len(views)}")
    radius_scale = float(np.hypot(width_px, height_px) / 2)
    centre = np.array([(width_px - 1) / 2, (height_px - 1) / 2])
    polynomial, poses = _initial_scaramuzza(views, centre, radius_scale)
    powers = np.arange(2, SCARAMUZZA_DEGREE + 1)
    intrinsics = np.concatenate([centre, [1.0, 0.0, polynomial[0]],
                                 polynomial[2:] * radius_scale ** (powers - 1)])
    extrinsics = np.concatenate([np.append(p.rotation_vector(), p.translation_mm) for p in poses])
    sizes = [len(v.image_points) for v in views]
    observed = np.concatenate([v.image_points for v in views])

    def unpack(vector: np.ndarray) -> tuple[ScaramuzzaCamera, list[RigidTransform]]:
        camera = _scaramuzza_from_vector(vector, width_px, height_px, radius_scale)
        blocks = vector[INTRINSIC_COUNT:].reshape(-1, 6)
        return camera, [RigidTransform.from_rotation_vector(b[:3], b[3:]) for b in blocks]

    def residuals(vector: np.ndarray) -> np.ndarray:
        camera, view_poses = unpack(vector)
        points = np.concatenate([pose.apply(view.object_points)
                                 for pose, view in zip(view_poses, views, strict=True)])
        difference = (camera.project(points) - observed).ravel()
        return np.nan_to_num(difference, nan=FAILED_PROJECTION_PX)

    sparsity = lil_matrix((2 * sum(sizes), INTRINSIC_COUNT + 6 * len(views)), dtype=int)
    sparsity[:, :INTRINSIC_COUNT] = 1
    start = 0
    for index, size in enumerate(sizes):
        first = INTRINSIC_COUNT + 6 * index
        sparsity[2 * start: 2 * (start + size), first: first + 6] = 1
        start += size
    # LSMR solves each step's linear problem to 1e-12, not its default 1e-6: the polynomial's
    # terms are nearly collinear, and steps solved to 1e-6 crawl along them until the limit.
    solution = least_squares(residuals, np.concatenate([intrinsics, extrinsics]),
                             jac_sparsity=sparsity, x_scale="jac", method="trf",
                             tr_options={"atol": 1e-12, "btol": 1e-12},
                             xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=FIT_MAX_EVALUATIONS)
    camera, poses = unpack(solution.x)
    return Calibration(camera, poses, views, reprojection_errors(camera, poses, views),
                       converged=solution.status > 0)
