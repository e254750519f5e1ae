"""Tilt-table images of a (true) rig: the calibration data a user records, with the truth."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from sds_model.paths import CONFIG
from sds_model.rig import Rig
from sds_recon.calibration.lasers import KnownSurface

from sds_sim.render import FrameRenderer, FrameTruth
from sds_sim.scenario import load_scenario

TILT_TABLE = CONFIG / "scenarios" / "tilt_table.yaml"
"""The scenario whose optics, sensor and wall reflections the series are drawn with."""


@dataclass(frozen=True)
class TiltSeries:
    """One still image per known surface, and what each image shows exactly."""

    images: list[np.ndarray]
    surfaces: list[KnownSurface]
    truths: list[FrameTruth]


def render_tilt_series(rig: Rig, angles_deg: list[float], axis: str = "x", scale: float = 1.0,
                       seed: int = 0, scenario: Path = TILT_TABLE) -> TiltSeries:
    """Images of the rig's liquid tilted by each angle about one axis (`x`: Z = −X tan γ,
    `y`: Z = −Y tan γ), flat, with the scenario's wall reflections and noise."""
    base = load_scenario(scenario, {"scale": scale, "seed": seed})
    series = replace(base, rig=rig, tilt_series_deg=tuple(angles_deg), tilt_series_axis=axis,
                     duration_s=float(len(angles_deg)), fps=30.0)
    renderer = FrameRenderer(series)
    images, surfaces, truths = [], [], []
    for step in range(len(angles_deg)):
        image, truth = renderer.render(30 * step)
        tilt_x, tilt_y = series.tilt_at(truth.time_s)
        images.append(image)
        surfaces.append(KnownSurface(series.offset_mm, tilt_x, tilt_y))
        truths.append(truth)
    return TiltSeries(images, surfaces, truths)
