"""A flickering light filmed through a rolling shutter: the clip `sds camera readout` measures.

A static textured scene (reflectance 0.4-1 per pixel, so that no row mean is flat) lit by a
lamp whose brightness is 1 + depth · w(f t), w a sine (a lamp on mains) or a square wave (an
LED's PWM). Row y of frame k is exposed from `RollingShutter.row_time_s(y)` after the frame's
time k / fps, over `exposure_s` (integrated over EXPOSURE_SAMPLES instants); a little sensor
noise, then H.264 as the camera writes it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from sds_camera.video_writer import VideoWriter
from sds_model.camera.rolling_shutter import RollingShutter

EXPOSURE_SAMPLES = 16
"""Instants a row's exposure is integrated over."""


@dataclass(frozen=True)
class Flicker:
    """The lamp: frequency [Hz], modulation depth (0-1), waveform ("sine" or "square")."""

    frequency_hz: float = 100.0
    depth: float = 0.5
    waveform: str = "sine"

    def brightness(self, time_s: np.ndarray) -> np.ndarray:
        """The light's brightness at each time (mean 1)."""
        phase = 2 * np.pi * self.frequency_hz * time_s
        wave = np.cos(phase) if self.waveform == "sine" else np.sign(np.cos(phase))
        return 1.0 + self.depth * wave


def flicker_clip(path: Path, width_px: int, height_px: int, fps: float, frames: int,
                 shutter: RollingShutter, flicker: Flicker, exposure_s: float,
                 seed: int = 0) -> Path:
    """Write the clip (H.264) and return its path."""
    rng = np.random.default_rng(seed)
    scene = 180.0 * rng.uniform(0.4, 1.0, (height_px, width_px))
    row_time = shutter.row_time_s(np.arange(height_px), height_px)
    offsets = exposure_s * ((np.arange(EXPOSURE_SAMPLES) + 0.5) / EXPOSURE_SAMPLES - 0.5)
    start_s = rng.uniform(0.0, 1.0)   # the lamp's phase at the first frame: unknown
    with VideoWriter(path, width_px, height_px, fps) as writer:
        for index in range(frames):
            times = start_s + index / fps + row_time[:, None] + offsets[None, :]
            light = flicker.brightness(times).mean(axis=1)
            grey = scene * light[:, None] + rng.normal(0.0, 1.5, scene.shape)
            image = np.clip(np.rint(grey), 0, 255).astype(np.uint8)
            writer.write(np.repeat(image[:, :, None], 3, axis=2))
    return path
