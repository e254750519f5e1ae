"""The camera's clock against the Arduino's, by acceleration and by the LED (`sds clock-link`).

Two independent links between a video and an Arduino log (SD card or serial capture):
- acceleration: the camera's own IMU (GPMF or sidecar, sds_camera.camera_imu), turned into
  the rig's frame by the rig file's camera pose, against the Arduino's accelerometer around
  the excitation (sds_arduino.clock.align_by_acceleration); needs no LED in view;
- LED: the sync LED's switch-on seen in the video (sds_camera.led, region `--led-roi`) against
  the Arduino's LED record. A switch shows in the first frame after it, so the frame time is
  late by U(0, T) for a frame period T: T/2 is taken off and σ = T/√12.
Where both exist, their difference is reported with its σ: a camera IMU whose clock is
offset from the frames, or a wrong LED region, shows there.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from sds_arduino.clock import ClockLink, align_by_acceleration, camera_offset_s
from sds_arduino.protocol import read_log, unwrap_time_s
from sds_camera.camera_imu import read_camera_imu
from sds_camera.frame_source import VideoFileSource
from sds_camera.led import LedDetector, switch_sigma_s, switch_times_s
from sds_model.errors import InputError
from sds_model.rig import Rig

STANDARD_GRAVITY = 9.80665
"""The Arduino logs accelerations in mg (sds_arduino.protocol)."""


@dataclass(frozen=True)
class ArduinoLog:
    """A log's accelerometer (device time [s], rig frame [m/s²]), its LED switch-on times [s]
    and the device time of its first record [s]."""

    accel_time_s: np.ndarray
    accel_m_s2: np.ndarray
    led_on_s: list[float]
    first_record_s: float


@dataclass(frozen=True)
class ClockLinks:
    """Camera time minus device time [s] by acceleration and by LED, each with its σ [s]."""

    acceleration: ClockLink | None
    led_offset_s: float | None
    led_sigma_s: float | None

    @property
    def disagreement_s(self) -> tuple[float, float] | None:
        """Acceleration minus LED offset [s] and the σ of that difference, where both exist."""
        if self.acceleration is None or self.led_offset_s is None or self.led_sigma_s is None:
            return None
        return (self.acceleration.offset_s - self.led_offset_s,
                float(np.hypot(self.acceleration.sigma_s, self.led_sigma_s)))


def read_arduino_log(path: Path) -> ArduinoLog:
    """The accelerometer and LED records of a protocol-v1 log; a one-line error without IMU."""
    records, _ = read_log(path)
    if not records:
        raise InputError(f"{path}: no valid protocol-v1 record")
    device_s = unwrap_time_s([r.t_us for r in records])
    imu = [k for k, r in enumerate(records) if r.kind == "IMU"]
    if len(imu) < 10:
        raise InputError(f"{path}: {len(imu)} accelerometer records, too few to link clocks")
    accel = np.array([records[k].values for k in imu], dtype=float) * STANDARD_GRAVITY / 1000
    led_on = [float(device_s[k]) for k, r in enumerate(records)
              if r.kind == "LED" and r.values[0]]
    return ArduinoLog(device_s[imu], accel, led_on, float(device_s[0]))


def video_led_on_s(video: Path, region: tuple[int, int, int, int]) -> tuple[list[float], float]:
    """Times [s] of the frames where the LED switched on, and the frame period [s]."""
    source = VideoFileSource(video)
    detector = LedDetector(region)
    times: list[float] = []
    try:
        for frame in source.frames():
            switch = detector.update(frame.index, frame.image)
            if switch is not None and switch.on:
                times.append(frame.time_ns * 1e-9)
    finally:
        source.close()
    return times, 1.0 / source.nominal_fps


def led_rows_on_s(video: Path, rig: Rig, region: tuple[int, int, int, int]
                  ) -> tuple[list[float], float]:
    """`video_led_on_s` of a video taken with `rig`, each time carried to when the LED's rows
    were exposed (its rolling shutter's delay after the frame's time), and the frame period."""
    on, period = video_led_on_s(video, region)
    led_row = region[1] + region[3] / 2
    row_delay_s = float(rig.camera_shutter.row_time_s(led_row, rig.camera.height_px))
    return [t + row_delay_s for t in on], period


def link_clocks(video: Path, log: ArduinoLog, rig: Rig,
                led_region: tuple[int, int, int, int] | None) -> ClockLinks:
    """Both links of a video to an Arduino log (None where a link has no data)."""
    acceleration = None
    imu = read_camera_imu(video)
    if imu is not None:
        in_rig = imu.accel_m_s2 @ rig.world_to_camera.rotation     # optical → world: Rᵀ v
        acceleration = align_by_acceleration(log.accel_time_s, log.accel_m_s2,
                                             imu.accel_time_s, in_rig)
    led_offset = led_sigma = None
    if led_region is not None and log.led_on_s:
        camera_on, period = led_rows_on_s(video, rig, led_region)
        offset = camera_offset_s(log.led_on_s, switch_times_s(camera_on, period))
        if np.isfinite(offset):
            led_offset, led_sigma = offset, switch_sigma_s(period)
    return ClockLinks(acceleration, led_offset, led_sigma)
