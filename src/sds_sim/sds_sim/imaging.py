"""A real camera's imaging, drawn at random within what a GoPro on ferrofluid gives.

The scenario's defaults render clean spots; these draws put in what the issue of real images
lists (speckle with a grain of pixels, saturation and bloom, motion blur over the auto
exposure's time, per-frame gain, ambient light and vignetting, shot and read noise, wall
reflections, one-frame glints, drop-outs), one effect at a time or all at once, as scenario
overrides (`load_scenario(path, overrides)`, or `dataclasses.replace` of its sections).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

RANGES: dict[str, dict[str, dict[str, tuple[float, float]]]] = {
    "speckle": {"optics": {"speckle": (0.3, 0.8), "speckle_grain_px": (0.5, 1.5)}},
    "saturation_bloom": {"optics": {"spot_peak": (500.0, 1500.0)},
                         "sensor": {"bloom_fraction": (0.05, 0.3),
                                    "bloom_sigma_px": (3.0, 8.0)}},
    "motion_blur": {"optics": {"exposure_s": (1 / 120, 1 / 30)}},
    "gain": {"sensor": {"gain_step": (0.01, 0.04)}},
    "ambient_vignetting": {"sensor": {"ambient_gradient": (0.1, 0.5), "vignetting": (0.2, 0.5),
                                      "background": (10.0, 40.0)}},
    "noise": {"sensor": {"read_noise": (1.5, 4.0)}},
    "reflections": {"disturbances": {"reflection_strength": (0.1, 0.5)}},
    "glints": {"disturbances": {"glint_rate_per_s": (5.0, 30.0)}},
    "dropouts": {"disturbances": {"occlusion_rate_per_s": (0.2, 1.0)}},
}
"""Each effect's scenario fields and the range each is drawn from, uniformly. Where the
numbers come from: speckle and its grain, the method notes (650 nm at f/2 gives a grain of
about one GoPro pixel at 4K; the grain here is in pixels of the rendered image, which the
benches draw at half scale; a moving liquid averages part of the pattern over the exposure);
spot peaks past saturation, the seed's diodes, bright enough to be seen through a neutral
filter; exposure, an auto exposure at 30 fps between 1/120 and 1/30 s; reflections, the
seed's Fig. 9a. The gain steps, read noise, ambient levels, glint rates and drop-out rates
are assumptions (no footage of the rig is at hand to measure them), wide on purpose."""
FIXED: dict[str, dict[str, dict[str, Any]]] = {
    "dropouts": {"disturbances": {"occlusion_frames": (1, 2)}},
    "motion_blur": {"optics": {"blur_samples": 7}},
}
"""Fields an effect sets to one value: drop-outs of one or two frames (foam, glints), and
enough sub-exposure samples for the longest exposure's blur."""
EFFECTS = tuple(RANGES)
"""The effects, in the order benches list them."""


def draw_imaging(rng: np.random.Generator, effects: tuple[str, ...] = EFFECTS
                 ) -> dict[str, dict[str, Any]]:
    """Scenario overrides (section → field → value) with each of `effects` drawn from its
    RANGES (every effect's draw is made, in EFFECTS order, so one effect's value does not
    depend on which others are on)."""
    overrides: dict[str, dict[str, Any]] = {}
    for effect in EFFECTS:
        drawn = {section: {name: float(rng.uniform(*bounds)) for name, bounds in fields.items()}
                 for section, fields in RANGES[effect].items()}
        if effect not in effects:
            continue
        for section, values in (*drawn.items(), *FIXED.get(effect, {}).items()):
            overrides.setdefault(section, {}).update(values)
    return overrides


def merged(base: Mapping[str, Any], overrides: Mapping[str, Mapping[str, Any]]
           ) -> dict[str, Any]:
    """Scenario overrides `base` with each section's `overrides` added to its own."""
    result = dict(base)
    for section, values in overrides.items():
        result[section] = {**(result.get(section) or {}), **values}
    return result
