"""The sync LED found in rendered frames, and the camera/device offset from its switch-ons."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sds_arduino.clock import camera_offset_s
from sds_camera.led import LedDetector
from sds_sim.render import FrameRenderer
from sds_sim.scenario import load_scenario


def test_led_switches_are_found_in_the_rendered_frames(repo: Path) -> None:
    scenario = load_scenario(repo / "config" / "scenarios" / "ground_kick.yaml",
                             {"duration_s": 0.7, "scale": 0.25})
    renderer = FrameRenderer(scenario)
    x, y = (np.array(scenario.events.led_position_px) * 0.25).astype(int)
    detector = LedDetector((x - 6, y - 6, 12, 12))
    switches = []
    for index in range(scenario.frame_count):
        frame, _ = renderer.render(index)
        switch = detector.update(index, frame)
        if switch is not None:
            switches.append((switch.frame, switch.on))
    on = [i for i in range(scenario.frame_count) if renderer.render(i)[1].led_on]
    assert switches == [(on[0], True), (on[-1] + 1, False)]
    assert on[0] / scenario.fps == pytest.approx(scenario.events.led_on_s, abs=1 / scenario.fps)


def test_camera_offset_is_the_median_over_paired_switch_ons() -> None:
    assert camera_offset_s([10.0, 20.0, 30.0], [110.0, 120.002, 129.999, 140.0]) == \
        pytest.approx(100.0)
    assert np.isnan(camera_offset_s([], [1.0]))
