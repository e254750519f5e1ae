"""`sds camera` and `sds resolution`: conversions between tools, and the seed's Fig. 7 numbers."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from sds_model.camera import PinholeCamera, load_camera, save_camera
from sds_model.camera.importers import ocamcalib_camera, read_camera_info
from sds_recon.resolution import vertical_resolution

SDS = str(Path(sys.executable).with_name("sds"))

CALIB_RESULTS = """\
#polynomial coefficients for the DIRECT mapping function (ocam_model.ss in MATLAB)

5 -3.100000e+02 0.000000e+00 1.400000e-03 -1.200000e-06 2.000000e-09

#polynomial coefficients for the inverse mapping function (ocam_model.invpol in MATLAB)

3 400.0 200.0 10.0

#center: "row" and "column", starting from 0 (C convention)

389.500000 517.250000

#affine parameters "c", "d", "e"

1.001000 0.002000 -0.003000

#image size: "height" and "width"

778 1032
"""


def sds(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([SDS, *args], capture_output=True, text=True, timeout=120, check=False)


def test_import_ocamcalib_results(tmp_path: Path) -> None:
    source = tmp_path / "calib_results.txt"
    source.write_text(CALIB_RESULTS)
    result = sds("camera", "import", "ocamcalib", str(source), "--out", str(tmp_path / "c.yaml"))
    assert result.returncode == 0, result.stderr
    camera = load_camera(tmp_path / "c.yaml")
    expected = ocamcalib_camera([-310.0, 0.0, 1.4e-3, -1.2e-6, 2e-9], 389.5, 517.25, 1.001, 0.002,
                                -0.003, 1032, 778, pixel_origin=0)
    assert (camera.width_px, camera.height_px) == (1032, 778)
    assert (camera.x0_px, camera.y0_px) == (517.25, 389.5)
    pixels = expected.image_grid(40)
    assert np.max(np.abs(camera.pixel_to_ray(pixels) - expected.pixel_to_ray(pixels))) < 1e-15


def test_import_matlab_fisheye_intrinsics_gives_the_shipped_gopro(tmp_path: Path,
                                                                  repo: Path) -> None:
    source = tmp_path / "gopro.yaml"
    source.write_text(yaml.safe_dump({
        "MappingCoefficients": [1722.6932, -1.2637e-4, 5.9090e-9, -1.0064e-11],
        "ImageSize": [2160, 3840], "DistortionCenter": [1926.6676, 1081.6723],
        "StretchMatrix": [[0.9986, 0.0012], [-4.4337e-4, 1.0]]}))
    result = sds("camera", "import", "matlab", str(source), "--out", str(tmp_path / "c.yaml"))
    assert result.returncode == 0, result.stderr
    imported = load_camera(tmp_path / "c.yaml")
    shipped = load_camera(repo / "config" / "cameras" / "gopro_hero5_session.yaml")
    pixels = shipped.image_grid(100)
    assert np.max(np.abs(imported.project(shipped.pixel_to_ray(pixels)) - pixels)) < 1e-9


def test_camera_info_export_and_import_round_trip(tmp_path: Path) -> None:
    camera = PinholeCamera(1920, 1080, 1400.5, 1399.25, 955.0, 541.5, k1=-0.2, k2=0.04, p1=1e-4)
    save_camera(camera, tmp_path / "pinhole.yaml")
    result = sds("camera", "camera-info", str(tmp_path / "pinhole.yaml"), "--out",
                 str(tmp_path / "info.yaml"))
    assert result.returncode == 0, result.stderr
    assert read_camera_info(tmp_path / "info.yaml") == camera
    result = sds("camera", "import", "camera-info", str(tmp_path / "info.yaml"), "--out",
                 str(tmp_path / "back.yaml"))
    assert result.returncode == 0 and load_camera(tmp_path / "back.yaml") == camera


def test_camera_info_export_refuses_the_omnidirectional_model(tmp_path: Path, repo: Path) -> None:
    gopro = repo / "config" / "cameras" / "gopro_hero5_session.yaml"
    result = sds("camera", "camera-info", str(gopro), "--out", str(tmp_path / "info.yaml"))
    assert result.returncode == 2 and "camera_info has no such model" in result.stderr
    assert not (tmp_path / "info.yaml").exists()


def test_import_of_a_wrong_file_is_a_clear_error(tmp_path: Path) -> None:
    (tmp_path / "junk.txt").write_text("not a calibration\n")
    result = sds("camera", "import", "ocamcalib", str(tmp_path / "junk.txt"), "--out",
                 str(tmp_path / "c.yaml"))
    assert result.returncode == 2 and "not an OCamCalib calib_results.txt" in result.stderr
    assert "Traceback" not in result.stderr


def test_resolution_of_the_gopro_matches_the_seed(tmp_path: Path) -> None:
    result = sds("resolution", "--radii-mm", "20", "60", "20", "--rings-mm", "20", "40", "55",
                 "--out", str(tmp_path))
    assert result.returncode == 0, result.stderr
    rows = np.loadtxt(tmp_path / "resolution.csv", delimiter=",", comments="#", skiprows=2)
    # Seed Fig. 7 (method notes): about 0.85, 0.43 mm/px at 20, 40 mm for vertical beams.
    assert rows[0, 0] == 20 and rows[0, 1] == pytest.approx(0.85, abs=0.01)
    assert rows[1, 0] == 40 and rows[1, 1] == pytest.approx(0.43, abs=0.01)
    assert (tmp_path / "resolution.png").stat().st_size > 10_000


def test_resolution_of_a_pinhole_is_the_analytic_one() -> None:
    # Ideal pinhole, spot at radius r on a surface D below: x = f r / D, so dZ/dx = D² / (f r).
    camera = PinholeCamera(4000, 4000, 1500.0, 1500.0, 1999.5, 1999.5)
    table = vertical_resolution(camera, [10.0, 30.0, 55.0], 170.0)
    assert table.along_x_mm_per_px == pytest.approx(170.0**2 / (1500.0 * np.array([10, 30, 55])),
                                                    rel=1e-6)
    # Beams tilted 20 deg: x = f (r + (D - H) tan t) / D, dx/dD = f (H tan t - r) / D² at D = H.
    tilted = vertical_resolution(camera, [0.0, 30.0], 170.0, np.radians(20))
    expected = 170.0**2 / (1500.0 * np.abs(170.0 * np.tan(np.radians(20)) - np.array([0, 30])))
    assert tilted.along_x_mm_per_px == pytest.approx(expected, rel=1e-6)


def test_line_laser_resolution_matches_the_seed(repo: Path) -> None:
    gopro = load_camera(repo / "config" / "cameras" / "gopro_hero5_session.yaml")
    # Seed Sec. 4.2: the line laser, tilted 20 deg and crossing the centre: about 0.27 mm/px.
    table = vertical_resolution(gopro, [0.0], 170.0, np.radians(20))
    assert table.along_x_mm_per_px[0] == pytest.approx(0.27, abs=0.01)
