"""The camera's own IMU: accelerometer and gyroscope samples on the video's media clock.

A GoPro writes them into the MP4 as a GPMF telemetry track (ACCL about 200 Hz in m/s², GYRO
about 400 Hz in rad/s, read here with GoPro's own parser, `py-gpmf-parser`). Other cameras and
the simulator give them as a sidecar CSV beside the video, `<video stem>.imu.csv`
(`write_sidecar` documents its columns). Both come out in the camera's optical frame as the
camera models use it (x right along the image rows, y down, z along the optical axis).

HERO5 Black and Session store each sample in the order Z, X, Y of GoPro's IMU axes (GoPro's
figure "IMU Orientation Follows the Right-hand Rule": X to the camera's left seen from behind,
Y backwards out of the rear screen, Z up). So optical x = −X, y = −Z, z = −Y, i.e. of a stored
sample s: (x, y, z) = (−s[1], −s[0], −s[2]). At rest a level, upright camera reads about
(0, −9.8, 0) m/s² (specific force, upwards), as in `karma.mp4`.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from sds_model.errors import InputError

HERO5_TO_OPTICAL = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
"""Optical-frame vector = HERO5_TO_OPTICAL @ stored (Z, X, Y) sample (a proper rotation)."""
SIDECAR_COLUMNS = ("sensor", "t_s", "x", "y", "z")
"""Sidecar CSV: sensor (accel [m/s²] or gyro [rad/s]), time on the video's clock [s], and
the sample in the camera's optical frame."""


class CameraImuError(InputError):
    """Telemetry that is there but cannot be read."""


@dataclass(frozen=True)
class CameraImu:
    """Accelerometer [m/s², specific force] and gyroscope [rad/s] samples, optical frame, each
    with its times on the video's media clock [s] (0 = the first frame; GoPro's start a little
    before it)."""

    accel_time_s: np.ndarray
    accel_m_s2: np.ndarray
    gyro_time_s: np.ndarray
    gyro_rad_s: np.ndarray
    source: str

    def __post_init__(self) -> None:
        for times, values in ((self.accel_time_s, self.accel_m_s2),
                              (self.gyro_time_s, self.gyro_rad_s)):
            if values.shape != (len(times), 3):
                raise CameraImuError(f"{self.source}: {values.shape} samples for {len(times)} "
                                     "times")


def read_gopro_imu(path: str | Path) -> CameraImu | None:
    """ACCL and GYRO of an MP4's GPMF track in the optical frame; None without such a track."""
    from py_gpmf_parser.gopro_telemetry_extractor import GoProTelemetryExtractor

    path = Path(path)
    if not path.is_file():
        raise CameraImuError(f"{path}: no such file")
    extractor = GoProTelemetryExtractor(str(path))
    extractor.open_source()
    try:
        if not extractor.handle:      # not an MP4, or one without a GPMF track
            return None
        accel, accel_t = extractor.extract_data("ACCL")
        gyro, gyro_t = extractor.extract_data("GYRO")
    finally:
        if extractor.handle:
            extractor.close_source()
    if len(accel) == 0 and len(gyro) == 0:
        return None
    return CameraImu(np.asarray(accel_t, float), _to_optical(accel), np.asarray(gyro_t, float),
                     _to_optical(gyro), f"{path} (GPMF)")


def _to_optical(stored: np.ndarray) -> np.ndarray:
    stored = np.asarray(stored, dtype=float).reshape(-1, 3)
    return stored @ HERO5_TO_OPTICAL.T


def sidecar_path(video: str | Path) -> Path:
    """Where a video's sidecar IMU file is: `<video stem>.imu.csv` beside it."""
    video = Path(video)
    return video.with_name(f"{video.stem}.imu.csv")


def read_sidecar(path: str | Path) -> CameraImu:
    """A sidecar CSV (SIDECAR_COLUMNS); a one-line error for a malformed one."""
    path = Path(path)
    rows: dict[str, list[tuple[float, float, float, float]]] = {"accel": [], "gyro": []}
    with path.open(newline="") as stream:
        reader = csv.DictReader(stream)
        if tuple(reader.fieldnames or ()) != SIDECAR_COLUMNS:
            raise CameraImuError(f"{path}: columns must be {', '.join(SIDECAR_COLUMNS)}")
        for number, row in enumerate(reader, start=2):
            try:
                rows[row["sensor"]].append((float(row["t_s"]), float(row["x"]),
                                            float(row["y"]), float(row["z"])))
            except (KeyError, ValueError) as error:
                raise CameraImuError(f"{path}:{number}: {error!r}") from None
    accel = np.array(rows["accel"]).reshape(-1, 4)
    gyro = np.array(rows["gyro"]).reshape(-1, 4)
    return CameraImu(accel[:, 0], accel[:, 1:], gyro[:, 0], gyro[:, 1:], str(path))


def write_sidecar(imu: CameraImu, path: str | Path) -> Path:
    """The samples as a sidecar CSV (accelerometer rows first, then gyroscope)."""
    path = Path(path)
    with path.open("w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow(SIDECAR_COLUMNS)
        for sensor, times, values in (("accel", imu.accel_time_s, imu.accel_m_s2),
                                      ("gyro", imu.gyro_time_s, imu.gyro_rad_s)):
            writer.writerows((sensor, f"{t:.6f}", *(f"{v:.6f}" for v in sample))
                             for t, sample in zip(times, values, strict=True))
    return path


def read_camera_imu(video: str | Path) -> CameraImu | None:
    """A video's IMU: its sidecar CSV if there is one, else its GPMF track; None if neither
    (a webcam's file, a folder of images)."""
    video = Path(video)
    sidecar = sidecar_path(video)
    if sidecar.is_file():
        return read_sidecar(sidecar)
    if video.is_file() and video.suffix.lower() in (".mp4", ".mov"):
        return read_gopro_imu(video)
    return None


def imu_samples(imu: CameraImu) -> list[tuple[float, str, np.ndarray]]:
    """Every sample (time [s], "accel" or "gyro", value) in time order."""
    samples = [(float(t), "accel", v) for t, v in zip(imu.accel_time_s, imu.accel_m_s2,
                                                       strict=True)]
    samples += [(float(t), "gyro", v) for t, v in zip(imu.gyro_time_s, imu.gyro_rad_s,
                                                      strict=True)]
    samples.sort(key=lambda sample: sample[0])
    return samples
