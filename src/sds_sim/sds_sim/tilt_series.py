"""Tilt-table images of a (true) rig: the calibration data a user records, with the truth."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from sds_model.paths import CONFIG
from sds_model.rig import Rig
from sds_recon.calibration.lasers import Accuracy, KnownSurface

from sds_sim.imaging import merged
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
    repeats: list[list[np.ndarray]] = field(default_factory=list)   # more frames of each


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


@dataclass(frozen=True)
class ReadingErrors:
    """How a user's readings of the known surfaces depart from the liquid's true pose (each
    drawn at random, seeded; 0: read exactly)."""

    about_axis_deg: float = 0.0    # a tilted frame's angle about its axis, uniform ± (the
                                   # seed's table: "0.5 deg accuracy")
    across_deg: float = 0.0        # the other angle of a tilted frame, normal σ
    level_deg: float = 0.0         # both angles of a level frame, normal σ (a spirit level)
    offset_mm: float = 0.0         # every fill level, normal σ (a measured volume)

    def accuracy(self, factor: float = 1.0) -> Accuracy:
        """What a user declares who knows these accuracies (`factor` × them: 0.1 declares them
        ten times too tight): the angle about a tilted frame's axis, uniform ±, as its σ."""
        return Accuracy(table_deg=factor * self.about_axis_deg / np.sqrt(3.0),
                        table_across_deg=factor * self.across_deg,
                        level_deg=factor * self.level_deg, fill_mm=factor * self.offset_mm)


def true_surfaces(readings: list[KnownSurface], errors: ReadingErrors,
                  rng: np.random.Generator) -> list[KnownSurface]:
    """The surfaces the liquid really takes when the user reads `readings` (a reading with
    both angles 0 is a level frame; one at offset 0 is at the first fill level, the world's
    Z = 0 by definition)."""
    truths = []
    for reading in readings:
        if reading.is_level:
            tilt = rng.normal(0.0, errors.level_deg, 2)
        else:
            about = rng.uniform(-1.0, 1.0) * errors.about_axis_deg
            across = rng.normal(0.0, errors.across_deg)
            tilt = np.array([about, across]) if reading.tilted_about_x \
                else np.array([across, about])
        tilt_x, tilt_y = np.radians(tilt)
        # the first fill level is the world's Z = 0, and a tilt keeps the liquid's volume
        offset = rng.normal(0.0, errors.offset_mm) if reading.offset_mm != 0.0 else 0.0
        truths.append(KnownSurface(reading.offset_mm + offset, reading.tilt_x_rad + tilt_x,
                                   reading.tilt_y_rad + tilt_y))
    return truths


def declared(readings: list[KnownSurface], errors: ReadingErrors, factor: float = 1.0
             ) -> list[KnownSurface]:
    """The readings with the σ a user declares for them, each angle its own (`factor` × the
    true accuracy: 0.1 declares it ten times too tight)."""
    accuracy = errors.accuracy(factor)
    return [accuracy.declare(r) for r in readings]


def render_surfaces(rig: Rig, surfaces: list[KnownSurface], scale: float = 1.0, seed: int = 0,
                    scenario: Path = TILT_TABLE, frames: int = 1,
                    imaging: dict[str, dict[str, Any]] | None = None) -> TiltSeries:
    """One still image of the rig's flat liquid on each surface (its true pose), with the
    scenario's wall reflections and noise (and `imaging`'s overrides of its sections,
    `sds_sim.imaging.draw_imaging`); with `frames` > 1, that many consecutive frames of
    each still (the liquid at rest, its speckle and noise new in every frame): the first is
    the image, the others its repeats."""
    base = load_scenario(scenario, merged({"scale": scale}, imaging or {}))
    images, truths, repeats = [], [], []
    for index, surface in enumerate(surfaces):
        still = replace(base, rig=rig, seed=seed + index, tilt_series_deg=(),
                        tilt_deg=(float(np.degrees(surface.tilt_x_rad)),
                                  float(np.degrees(surface.tilt_y_rad))),
                        offset_mm=surface.offset_mm, duration_s=max(1.0, frames / 30.0),
                        fps=30.0)
        renderer = FrameRenderer(still)
        rendered = [renderer.render(k) for k in range(frames)]
        images.append(rendered[0][0])
        truths.append(rendered[0][1])
        repeats.append([image for image, _ in rendered[1:]])
    return TiltSeries(images, list(surfaces), truths, repeats if frames > 1 else [])
