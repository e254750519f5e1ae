"""The rolling shutter: its row times as the camera file states them, and `sds camera readout`
measuring a readout from a rendered flicker clip (the simulator's truth, H.264)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from sds_camera.readout import video_readout
from sds_model.camera.model import CameraModelError
from sds_model.camera.rolling_shutter import RollingShutter, rolling_shutter
from sds_sim.flicker import Flicker, flicker_clip

SDS = str(Path(sys.executable).with_name("sds"))


def test_a_row_is_exposed_its_share_of_the_readout_after_the_first() -> None:
    shutter = RollingShutter(0.02)
    np.testing.assert_allclose(shutter.row_time_s([0.0, 540.0, 2159.0], 2160),
                               [0.0, 0.005, 0.02 * 2159 / 2160])
    upwards = RollingShutter(0.02, "bottom_to_top")
    np.testing.assert_allclose(upwards.row_time_s([2159.0, 0.0], 2160), [0.0, 0.02 * 2159 / 2160])
    assert rolling_shutter({}) == RollingShutter(0.0)          # absent: a global shutter
    assert rolling_shutter({"readout_s": 0.025, "readout_direction": "bottom_to_top"}) == \
        RollingShutter(0.025, "bottom_to_top")
    for content, message in (({"readout_s": -0.01}, "from 0"), ({"readout_s": "fast"}, "seconds"),
                             ({"readout_direction": "upwards"}, "one of")):
        with pytest.raises(CameraModelError, match=message):
            rolling_shutter(content)


@pytest.mark.parametrize("readout_s, flicker_hz, waveform, direction", [
    (0.020, 100.0, "sine", "top_to_bottom"),      # a lamp on 50 Hz mains
    (0.030, 110.0, "square", "bottom_to_top"),    # an LED's PWM
    (None, 100.0, "square", "top_to_bottom"),     # a random one
])
def test_sds_camera_readout_recovers_the_rendered_readout(
        readout_s: float | None, flicker_hz: float, waveform: str, direction: str,
        tmp_path: Path) -> None:
    rng = np.random.default_rng(int(flicker_hz) + len(waveform))
    readout_s = readout_s if readout_s is not None else float(rng.uniform(0.005, 0.032))
    exposure_s = float(rng.uniform(0.3e-3, 0.4 / flicker_hz))
    clip = flicker_clip(tmp_path / "flicker.mp4", 1280, 720, 30.0, 20,
                        RollingShutter(readout_s, direction),
                        Flicker(flicker_hz, 0.3, waveform), exposure_s, seed=7)
    done = subprocess.run([SDS, "camera", "readout", str(clip), "--flicker-hz",
                           str(flicker_hz)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    found = re.search(r"([\d.]+) ms ± ([\d.]+) ms", done.stdout)
    assert found, done.stdout
    measured_ms, sigma_ms = float(found.group(1)), float(found.group(2))
    assert abs(measured_ms - readout_s * 1e3) < 0.5, (measured_ms, readout_s)
    assert abs(measured_ms - readout_s * 1e3) < 4 * sigma_ms + 0.002, (measured_ms, sigma_ms)


def test_bands_that_stand_still_or_no_flicker_are_refused_in_one_line(tmp_path: Path) -> None:
    standing = flicker_clip(tmp_path / "standing.mp4", 640, 360, 30.0, 6, RollingShutter(0.02),
                            Flicker(120.0, 0.3), 1e-3)
    done = subprocess.run([SDS, "camera", "readout", str(standing), "--flicker-hz", "120"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "stand still" in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    steady = flicker_clip(tmp_path / "steady.mp4", 640, 360, 30.0, 6, RollingShutter(0.02),
                          Flicker(100.0, 0.0), 1e-3)
    with pytest.raises(ValueError, match="no flicker bands"):
        video_readout(steady, 100.0)
