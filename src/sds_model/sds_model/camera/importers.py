"""Camera models from other tools: OCamCalib, MATLAB fisheyeIntrinsics, ROS camera_info."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import ArrayLike

from sds_model.camera.files import read_yaml
from sds_model.camera.model import CameraModelError
from sds_model.camera.pinhole import PinholeCamera
from sds_model.camera.scaramuzza import ScaramuzzaCamera
from sds_model.geometry import RigidTransform

OCAMCALIB_TO_SDS = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
"""OCamCalib's camera frame (x along rows, y along columns, z against the view) → SDS's."""


def ocamcalib_camera(ss: ArrayLike, centre_row: float, centre_col: float, c: float, d: float,
                     e: float, width_px: int, height_px: int, pixel_origin: int
                     ) -> ScaramuzzaCamera:
    """OCamCalib's model (ss ascending, centre (row, col), affine [c d; e 1] on (row, col)).

    OCamCalib: [row − xc; col − yc] = [[c, d], [e, 1]] [u; v], ray = (u, v, ss(|u, v|)), a0 < 0.
    In SDS order (x = column, y = row) the affine is [[1, e], [d, c]]; dividing it by c gives the
    seed's form [[c', e'], [m', 1]] and rescales the radius, so a_i' = a_i c^(1 − i); the frame
    change (v, u, −z) flips the polynomial's sign. The projection is unchanged.
    """
    coefficients = np.asarray(ss, dtype=float)
    powers = np.arange(len(coefficients))
    polynomial = 0.0 - coefficients * float(c) ** (1 - powers)  # 0.0 - keeps a1 = +0.0
    return ScaramuzzaCamera(int(width_px), int(height_px), tuple(polynomial),
                            float(centre_col) - pixel_origin, float(centre_row) - pixel_origin,
                            c=1.0 / c, e=e / c, m=d / c)


def read_ocamcalib_results(path: str | Path) -> ScaramuzzaCamera:
    """Read OCamCalib's `calib_results.txt` (C export: 0-based centre, row then column)."""
    path = Path(path)
    try:
        rows = [line.split() for line in path.read_text().splitlines()
                if line.strip() and not line.lstrip().startswith("#")]
        pol = [float(v) for v in rows[0][1:1 + int(rows[0][0])]]
        centre_row, centre_col = (float(v) for v in rows[2][:2])
        c, d, e = (float(v) for v in rows[3][:3])
        height, width = (int(v) for v in rows[4][:2])
    except (OSError, IndexError, ValueError) as error:
        raise CameraModelError(f"{path} is not an OCamCalib calib_results.txt: {error}") from error
    return ocamcalib_camera(pol, centre_row, centre_col, c, d, e, width, height, pixel_origin=0)


def ocamcalib_extrinsics(rr: ArrayLike) -> RigidTransform:
    """Board → SDS camera frame from OCamCalib's RRfin slice [r1 r2 t] (3×3)."""
    rr = np.asarray(rr, dtype=float)
    r1, r2, t = rr[:, 0], rr[:, 1], rr[:, 2]
    rotation = np.column_stack([r1, r2, np.cross(r1, r2)])
    u, _, vt = np.linalg.svd(rotation)
    return RigidTransform(OCAMCALIB_TO_SDS @ (u @ vt), OCAMCALIB_TO_SDS @ t)


def matlab_fisheye_camera(mapping_coefficients: ArrayLike, image_size: ArrayLike,
                          distortion_center: ArrayLike,
                          stretch_matrix: ArrayLike = ((1.0, 0.0), (0.0, 1.0))) -> ScaramuzzaCamera:
    """MATLAB fisheyeIntrinsics: [a0 a2 a3 a4], ImageSize [rows cols], 1-based x = column centre.

    MATLAB's StretchMatrix [[c, d], [e, 1]] acts on (x, y) offsets, so it is the seed's Q with
    e_seed = d and m_seed = e; a0 > 0 and the axis is +z, as in SDS.
    """
    a0, a2, a3, a4 = np.asarray(mapping_coefficients, dtype=float).tolist()
    rows, cols = np.asarray(image_size, dtype=float).astype(int).tolist()
    cx, cy = (np.asarray(distortion_center, dtype=float) - 1.0).tolist()
    stretch = np.asarray(stretch_matrix, dtype=float)
    if stretch[1, 1] != 1.0:
        raise CameraModelError(f"StretchMatrix must be [c d; e 1], got {stretch.tolist()}")
    return ScaramuzzaCamera(cols, rows, (a0, 0.0, a2, a3, a4), cx, cy,
                            c=stretch[0, 0], e=stretch[0, 1], m=stretch[1, 0])


def read_matlab_fisheye(path: str | Path) -> ScaramuzzaCamera:
    """Read MATLAB fisheyeIntrinsics properties saved as YAML or JSON (the property names:
    MappingCoefficients, ImageSize, DistortionCenter and optionally StretchMatrix)."""
    content = read_yaml(path)
    try:
        return matlab_fisheye_camera(content["MappingCoefficients"], content["ImageSize"],
                                     content["DistortionCenter"],
                                     content.get("StretchMatrix", ((1.0, 0.0), (0.0, 1.0))))
    except CameraModelError:
        raise
    except (KeyError, TypeError, ValueError) as error:
        raise CameraModelError(f"{path} is not a fisheyeIntrinsics file: {error!r}") from error


def _matrix(content: dict[str, Any], key: str, shape: tuple[int, int]) -> np.ndarray:
    entry = content[key]
    data = np.asarray(entry["data"] if isinstance(entry, dict) else entry, dtype=float)
    return data.reshape(shape)


def camera_info_to_pinhole(content: dict[str, Any]) -> PinholeCamera:
    """A pinhole camera from ROS camera_info YAML content (camera_calibration_parsers layout)."""
    model = content.get("distortion_model", "plumb_bob")
    if model != "plumb_bob":
        raise CameraModelError(f"only the plumb_bob distortion model is supported, got {model!r}")
    try:
        k = _matrix(content, "camera_matrix", (3, 3))
        d = np.asarray(content["distortion_coefficients"]["data"], dtype=float)
        return PinholeCamera.from_opencv(k, d, int(content["image_width"]),
                                         int(content["image_height"]))
    except CameraModelError:
        raise
    except (KeyError, TypeError, ValueError) as error:
        raise CameraModelError(f"not a camera_info YAML: {error!r}") from error


def read_camera_info(path: str | Path) -> PinholeCamera:
    """Read a ROS camera_info YAML file (plumb_bob)."""
    return camera_info_to_pinhole(read_yaml(path))


def pinhole_to_camera_info(camera: PinholeCamera, camera_name: str = "sds_camera"
                           ) -> dict[str, Any]:
    """ROS camera_info YAML content (plumb_bob, no rectification) for a pinhole camera."""
    k = camera.camera_matrix()
    projection = np.column_stack([k, np.zeros(3)])

    def block(matrix: np.ndarray) -> dict[str, Any]:
        rows, cols = matrix.shape
        return {"rows": rows, "cols": cols, "data": [float(v) for v in matrix.ravel()]}

    return {"image_width": camera.width_px, "image_height": camera.height_px,
            "camera_name": camera_name, "camera_matrix": block(k),
            "distortion_model": "plumb_bob",
            "distortion_coefficients": block(camera.distortion_coefficients().reshape(1, 5)),
            "rectification_matrix": block(np.eye(3)), "projection_matrix": block(projection)}


def write_camera_info(camera: PinholeCamera, path: str | Path,
                      camera_name: str = "sds_camera") -> Path:
    """Write a ROS camera_info YAML file that camera_calibration_parsers reads."""
    path = Path(path)
    path.write_text(yaml.safe_dump(pinhole_to_camera_info(camera, camera_name), sort_keys=False,
                                   default_flow_style=None))
    return path
