"""Camera models against OpenCV, OCamCalib's own formulas and analytic round trips."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from sds_model.camera import (
    CameraModelError,
    PinholeCamera,
    ScaramuzzaCamera,
    camera_from_dict,
    load_camera,
    save_camera,
)
from sds_model.camera.importers import (
    camera_info_to_pinhole,
    matlab_fisheye_camera,
    ocamcalib_camera,
    pinhole_to_camera_info,
    read_camera_info,
    write_camera_info,
)
from sds_model.geometry import RigidTransform

TABLE_2 = {"mapping": [1722.6932, -1.2637e-4, 5.9090e-9, -1.0064e-11], "size": [2160, 3840],
           "centre": [1926.6676, 1081.6723], "stretch": [[0.9986, 0.0012], [-4.4337e-4, 1.0]]}


def random_pinhole(rng: np.random.Generator, skew_angle_rad: float = math.pi / 2) -> PinholeCamera:
    """A 1280×960 camera with random focal lengths, centre and moderate distortion."""
    return PinholeCamera(1280, 960, rng.uniform(900, 1300), rng.uniform(900, 1300),
                         rng.uniform(600, 680), rng.uniform(440, 520), skew_angle_rad,
                         k1=rng.uniform(-0.25, 0.1), k2=rng.uniform(-0.05, 0.1),
                         k3=rng.uniform(-0.02, 0.02), p1=rng.uniform(-2e-3, 2e-3),
                         p2=rng.uniform(-2e-3, 2e-3))


def gopro() -> ScaramuzzaCamera:
    return matlab_fisheye_camera(TABLE_2["mapping"], TABLE_2["size"], TABLE_2["centre"],
                                 TABLE_2["stretch"])


@pytest.mark.parametrize("seed", range(5))
def test_pinhole_projection_equals_opencv(seed: int) -> None:
    rng = np.random.default_rng(seed)
    camera = random_pinhole(rng)
    points = rng.uniform([-400, -300, 500], [400, 300, 1500], (2000, 3))
    expected, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), camera.camera_matrix(),
                                    camera.distortion_coefficients())
    assert np.max(np.abs(camera.project(points) - expected.reshape(-1, 2))) < 1e-9


def test_pinhole_skew_follows_opencv_camera_matrix() -> None:
    rng = np.random.default_rng(7)
    camera = random_pinhole(rng, skew_angle_rad=math.radians(89.5))
    k = camera.camera_matrix()
    assert k[0, 1] == pytest.approx(-camera.alpha_px / math.tan(math.radians(89.5)))
    points = rng.uniform([-400, -300, 500], [400, 300, 1500], (500, 3))
    # cv2.projectPoints ignores K[0,1]: distort with it (K = I), then apply K as Bouguet does.
    distorted, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), np.eye(3),
                                     camera.distortion_coefficients())
    expected = distorted.reshape(-1, 2) @ k[:2, :2].T + k[:2, 2]
    assert np.max(np.abs(camera.project(points) - expected)) < 1e-9
    grid = camera.image_grid(16)
    assert np.nanmax(np.abs(camera.project(camera.pixel_to_ray(grid)) - grid)) < 1e-6


@pytest.mark.parametrize("seed", range(5))
def test_pinhole_undistortion_round_trip_over_the_image(seed: int) -> None:
    camera = random_pinhole(np.random.default_rng(seed))
    pixels = camera.image_grid(4)
    rays = camera.pixel_to_ray(pixels)
    assert not np.isnan(rays).any()
    assert np.allclose(np.linalg.norm(rays, axis=1), 1.0)
    assert np.max(np.abs(camera.project(rays) - pixels)) < 1e-6


def test_pinhole_rays_agree_with_opencv_undistort_points() -> None:
    camera = random_pinhole(np.random.default_rng(11))
    pixels = camera.image_grid(40)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    normalised = cv2.undistortPoints(pixels.reshape(-1, 1, 2), camera.camera_matrix(),
                                     camera.distortion_coefficients(), criteria=criteria)
    rays = camera.pixel_to_ray(pixels)
    assert np.max(np.abs(rays[:, :2] / rays[:, 2:] - normalised.reshape(-1, 2))) < 1e-6


def test_pinhole_pixels_beyond_the_distortion_fold_get_no_ray() -> None:
    # k1 = -0.35 folds Eq. 3 at r = 1.03 (distorted radius 0.69): the corners of this image
    # (distorted radius 0.8) are reached by no ray, so they must come back NaN, not invented.
    camera = PinholeCamera(1280, 960, 1000, 1000, 639.5, 479.5, k1=-0.35)
    undistorted = np.linspace(0, 2, 20001)
    fold = np.max(undistorted * (1 - 0.35 * undistorted**2))
    pixels = camera.image_grid(8)
    rays = camera.pixel_to_ray(pixels)
    reachable = np.hypot(*((pixels - [639.5, 479.5]) / 1000).T) < fold
    assert np.isnan(rays[~reachable]).all() and (~reachable).sum() > 100
    assert np.max(np.abs(camera.project(rays[reachable]) - pixels[reachable])) < 1e-6


def test_pinhole_points_behind_the_camera_are_not_imaged() -> None:
    camera = random_pinhole(np.random.default_rng(1))
    projected = camera.project([[0.1, 0.2, -1.0], [0.0, 0.0, 0.0], [0.1, 0.1, 1.0]])
    assert np.isnan(projected[:2]).all() and np.isfinite(projected[2]).all()


def test_scaramuzza_round_trip_over_the_whole_gopro_image() -> None:
    camera = gopro()
    assert camera.covers_image
    pixels = np.concatenate([camera.image_grid(4),
                             np.random.default_rng(0).uniform([0, 0], [3839, 2159], (20000, 2))])
    rays = camera.pixel_to_ray(pixels)
    assert not np.isnan(rays).any()
    assert np.max(np.abs(camera.project(rays) - pixels)) < 1e-6


def test_scaramuzza_projection_returns_the_point_direction() -> None:
    camera = gopro()
    rng = np.random.default_rng(3)
    pixels = rng.uniform([0, 0], [3839, 2159], (5000, 2))
    distances = rng.uniform(50, 500, (5000, 1))
    points = camera.pixel_to_ray(pixels) * distances
    rays = camera.pixel_to_ray(camera.project(points))
    assert np.max(np.linalg.norm(rays - points / distances, axis=1)) < 1e-9


def test_scaramuzza_field_of_view_matches_the_seed() -> None:
    camera = gopro()
    row, column = camera.y0_px, camera.x0_px
    rays = camera.pixel_to_ray([[0, row], [3839, row], [column, 0], [column, 2159]])
    angles = np.degrees(np.arctan2(np.hypot(rays[:, 0], rays[:, 1]), rays[:, 2]))
    # Seed Sec. 4.2: horizontal FOV 118.9 deg, vertical 69.7 deg.
    assert angles[0] + angles[1] == pytest.approx(118.9, abs=1.5)
    assert angles[2] + angles[3] == pytest.approx(69.7, abs=1.0)


def test_scaramuzza_points_outside_the_field_are_nan() -> None:
    camera = gopro()
    projected = camera.project([[0, 0, -100.0], [100.0, 0, -1.0], [0, 0, 100.0]])
    assert np.isnan(projected[:2]).all()
    assert projected[2] == pytest.approx([camera.x0_px, camera.y0_px])


def ocamcalib_cam2world(row_col: np.ndarray, ss: list[float], xc: float, yc: float, c: float,
                        d: float, e: float) -> np.ndarray:
    """OCamCalib's C cam2world (ocam_functions.cpp), transcribed: rows, columns → unit rays."""
    invdet = 1 / (c - d * e)
    xp = invdet * ((row_col[:, 0] - xc) - d * (row_col[:, 1] - yc))
    yp = invdet * (-e * (row_col[:, 0] - xc) + c * (row_col[:, 1] - yc))
    zp = np.polynomial.polynomial.polyval(np.hypot(xp, yp), ss)
    rays = np.column_stack([xp, yp, zp])
    return rays / np.linalg.norm(rays, axis=1, keepdims=True)


def test_ocamcalib_import_reproduces_ocamcalib_rays() -> None:
    ss, xc, yc, c, d, e = [-206.3866, 0.0, 2.16561e-3, -4.495456e-6, 1.810639e-8], 241.02, \
        385.78, 0.998881, -0.042038, 0.045079
    camera = ocamcalib_camera(ss, xc, yc, c, d, e, 748, 480, pixel_origin=0)
    pixels = camera.image_grid(10)
    expected = ocamcalib_cam2world(pixels[:, ::-1], ss, xc, yc, c, d, e)
    # OCamCalib's frame is (row axis, column axis, -optical axis): swap x/y and flip z.
    ours = camera.pixel_to_ray(pixels)
    assert np.max(np.abs(ours - expected[:, [1, 0, 2]] * [1, 1, -1])) < 1e-12
    assert camera.polynomial[0] > 0 and camera.stretch[1, 1] == 1.0


def test_matlab_import_equals_the_shipped_gopro_file(repo: Path) -> None:
    shipped = load_camera(repo / "config" / "cameras" / "gopro_hero5_session.yaml")
    assert isinstance(shipped, ScaramuzzaCamera)
    assert (shipped.x0_px, shipped.y0_px) == pytest.approx((1925.6676, 1080.6723))
    pixels = shipped.image_grid(64)
    assert np.max(np.abs(shipped.pixel_to_ray(pixels) - gopro().pixel_to_ray(pixels))) < 1e-15


@pytest.mark.parametrize("camera", [random_pinhole(np.random.default_rng(2), math.radians(89.0)),
                                    gopro()], ids=["pinhole", "scaramuzza"])
def test_camera_file_round_trip(camera, tmp_path: Path) -> None:
    path = save_camera(camera, tmp_path / "camera.yaml", comment="a test camera " * 20)
    loaded = load_camera(path)
    assert type(loaded) is type(camera)
    pixels = camera.image_grid(50)
    assert np.max(np.abs(loaded.pixel_to_ray(pixels) - camera.pixel_to_ray(pixels))) < 1e-14


def test_pixel_origin_one_shifts_the_centre() -> None:
    content = {"model": "pinhole", "image_size": [640, 480], "pixel_origin": 1,
               "parameters": {"alpha_px": 500, "beta_px": 500, "centre_px": [320.5, 240.5]}}
    camera = camera_from_dict(content)
    assert (camera.x0_px, camera.y0_px) == (319.5, 239.5)
    assert camera.project([[0, 0, 1.0]])[0] == pytest.approx([319.5, 239.5])


@pytest.mark.parametrize("content, message", [
    ({"model": "fisheye", "image_size": [10, 10], "parameters": {}}, "model must be one of"),
    ({"model": "pinhole", "parameters": {}}, "lacks 'image_size'"),
    ({"model": "pinhole", "image_size": [640, 480], "parameters": {"alpha_px": 1}}, "bad pinhole"),
    ({"model": "pinhole", "image_size": [640, 480], "pixel_origin": 2, "parameters": {}},
     "pixel_origin"),
    ({"model": "scaramuzza", "image_size": [748, 480],
      "parameters": {"polynomial": [-206.4, 0, 2.2e-3], "centre_px": [385, 241]}}, "a0 must be"),
    ({"model": "scaramuzza", "image_size": [748, 480],
      "parameters": {"polynomial": [200, 0, 0, 0, 1e-6], "centre_px": [385, 241]}}, "one-to-one"),
    ({"model": "pinhole", "image_size": [640, 480], "parameters": {
        "alpha_px": 500, "beta_px": 500, "centre_px": [320, 240], "distortion": {"k4": 1}}},
     "unknown distortion"),
])
def test_bad_camera_files_are_refused_with_a_reason(content: dict, message: str,
                                                    tmp_path: Path) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(content))
    with pytest.raises(CameraModelError, match=message):
        load_camera(path)


def test_unreadable_camera_file_is_a_camera_model_error(tmp_path: Path) -> None:
    with pytest.raises(CameraModelError, match="cannot read"):
        load_camera(tmp_path / "missing.yaml")
    (tmp_path / "broken.yaml").write_text("model: [unclosed")
    with pytest.raises(CameraModelError, match="cannot read"):
        load_camera(tmp_path / "broken.yaml")


def test_camera_info_round_trip_keeps_the_projection(tmp_path: Path) -> None:
    camera = random_pinhole(np.random.default_rng(4), math.radians(89.7))
    path = write_camera_info(camera, tmp_path / "camera_info.yaml")
    loaded = read_camera_info(path)
    assert loaded.skew_angle_rad == pytest.approx(camera.skew_angle_rad, abs=1e-12)
    points = np.random.default_rng(0).uniform([-1, -1, 2], [1, 1, 4], (100, 3))
    assert np.max(np.abs(loaded.project(points) - camera.project(points))) < 1e-9


def test_camera_info_from_ros_documentation_layout() -> None:
    # camera_calibration_parsers' example file (narrow_stereo), as ROS writes it.
    content = yaml.safe_load("""
image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix: {rows: 3, cols: 3, data: [430.15, 0, 311.71, 0, 430.48, 221.06, 0, 0, 1]}
distortion_model: plumb_bob
distortion_coefficients: {rows: 1, cols: 5, data: [-0.337, 0.116, 0.00287, -0.00004, 0]}
rectification_matrix: {rows: 3, cols: 3, data: [1, 0, 0, 0, 1, 0, 0, 0, 1]}
projection_matrix: {rows: 3, cols: 4, data: [357.5, 0, 303.1, 0, 0, 392.5, 219.8, 0, 0, 0, 1, 0]}
""")
    camera = camera_info_to_pinhole(content)
    assert (camera.alpha_px, camera.beta_px, camera.x0_px, camera.y0_px) == \
        (430.15, 430.48, 311.71, 221.06)
    assert camera.k1 == -0.337 and camera.p2 == -0.00004
    assert pinhole_to_camera_info(camera)["distortion_coefficients"]["data"] == \
        content["distortion_coefficients"]["data"]
    with pytest.raises(CameraModelError, match="plumb_bob"):
        camera_info_to_pinhole({**content, "distortion_model": "equidistant"})


def test_rigid_transform_matches_rodrigues_and_inverts() -> None:
    rng = np.random.default_rng(5)
    rvec, tvec = rng.normal(size=3), rng.normal(size=3) * 100
    transform = RigidTransform.from_rotation_vector(rvec, tvec)
    points = rng.normal(size=(50, 3)) * 100
    expected = points @ cv2.Rodrigues(rvec)[0].T + tvec
    assert np.allclose(transform.apply(points), expected, atol=1e-9)
    assert np.allclose(transform.inverse().apply(expected), points, atol=1e-9)
    assert np.allclose(transform.rotation_vector(), rvec)
    other = RigidTransform.from_rotation_vector(rng.normal(size=3), rng.normal(size=3))
    assert np.allclose(other.compose(transform).apply(points), other.apply(expected), atol=1e-9)
    with pytest.raises(ValueError, match="orthonormal"):
        RigidTransform(np.diag([1.0, 1.0, -1.0]))


def test_a_rotation_is_accepted_where_np_allclose_accepted_it() -> None:
    """The cheap orthonormality check keeps np.allclose's tolerance (atol 1e-9, rtol 1e-5)."""
    outcomes = []
    for row, column, change in [(0, 0, 4e-6), (1, 1, -4e-6), (0, 1, 1e-7), (2, 0, 5e-10),
                                (0, 0, 2e-5)]:
        rotation = np.eye(3)
        rotation[row, column] += change
        expected = np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-9)
        try:
            RigidTransform(rotation)
            accepted = True
        except ValueError:
            accepted = False
        assert accepted == expected, (row, column, change)
        outcomes.append(accepted)
    assert any(outcomes) and not all(outcomes)
    with pytest.raises(ValueError, match="proper orthonormal"):
        RigidTransform(np.diag([1.0, 1.0, -1.0]))


def test_symmetric_stretch_forms_the_same_image_with_a_roll() -> None:
    camera = gopro()
    symmetric, roll = camera.with_symmetric_stretch()
    assert symmetric.e == pytest.approx(symmetric.m, abs=1e-15) and symmetric.stretch[1, 1] == 1
    rolled = RigidTransform.from_rotation_vector([0, 0, roll], np.zeros(3))
    rays = camera.pixel_to_ray(camera.image_grid(64))
    pixels = camera.project(rays)
    assert np.max(np.abs(symmetric.project(rolled.apply(rays)) - pixels)) < 1e-6


@pytest.mark.parametrize("camera", [random_pinhole(np.random.default_rng(8)), gopro()],
                         ids=["pinhole", "scaramuzza"])
def test_scaled_camera_sees_the_same_rays_at_scaled_pixels(camera) -> None:
    small = camera.scaled(0.25)
    assert (small.width_px, small.height_px) == (round(camera.width_px / 4),
                                                 round(camera.height_px / 4))
    pixels = camera.image_grid(37)
    rays = camera.pixel_to_ray(pixels)
    assert np.max(np.abs(small.project(rays) - ((pixels + 0.5) * 0.25 - 0.5))) < 1e-9
