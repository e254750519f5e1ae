"""The simulator's real-camera imaging against its own definitions: speckle statistics and
grain, bloom, auto-exposure gain, vignetting, glints, drop-outs, and the effects' draws."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sds_sim.imaging import EFFECTS, RANGES, draw_imaging, merged
from sds_sim.render import FrameRenderer, _Layer
from sds_sim.scenario import load_scenario


def renderer(repo: Path, overrides: dict, seconds: float = 0.2) -> FrameRenderer:
    """A quarter-scale ground kick with the given scenario overrides."""
    base = {"duration_s": seconds, "scale": 0.5, "seed": 3}
    return FrameRenderer(load_scenario(repo / "config" / "scenarios" / "ground_kick.yaml",
                                       merged(base, overrides)))


@pytest.mark.parametrize(("contrast", "grain_px"), [(1.0, 2.0), (0.5, 1.0), (1.0, 3.0)])
def test_speckle_has_its_contrast_exponential_statistics_and_grain(contrast: float,
                                                                   grain_px: float) -> None:
    """On uniform light: σ/mean is the contrast; fully developed speckle is exponential (a
    tenth of the mean or less on 1 − e^−0.1 of the pixels); the intensity's autocorrelation
    at a lag of one grain σ is e^−½ (the field's Gaussian correlation, squared)."""
    layer = _Layer(600, 600)
    layer._windows.append(((0, 600, 0, 600), np.ones((600, 600), np.float32)))
    layer.speckle(np.random.default_rng(5), contrast, grain_px)
    (_, values), = layer.windows()
    assert abs(values.mean() - 1.0) < 1e-5
    assert values.std() / values.mean() == pytest.approx(contrast, rel=0.1)
    if contrast == 1.0:
        assert np.mean(values < 0.1) == pytest.approx(1 - np.exp(-0.1), abs=0.01)
    lag = int(grain_px)
    centred = values - values.mean()
    correlation = np.mean(centred[:, lag:] * centred[:, :-lag]) / centred.var()
    assert correlation == pytest.approx(np.exp(-0.5 * (lag / grain_px) ** 2), abs=0.06)


def test_bloom_puts_a_halo_around_saturated_spots_only(repo: Path) -> None:
    """A diode far past saturation with bloom (σ 8 px at this scale) lights a ring 12-18 px
    from its centre, where its own Gaussian (σ about 2.6 px) has nothing; the same spot
    without bloom does not."""
    optics = {"spot_peak": 3000.0, "speckle": 0.0}
    rings = {}
    for fraction in (0.0, 0.2):
        r = renderer(repo, {"optics": optics, "sensor": {"bloom_fraction": fraction,
                                                         "bloom_sigma_px": 16.0,
                                                         "read_noise": 0.0,
                                                         "shot_noise": False}})
        image, truth = r.render(0)
        x, y = np.round(truth.spot_exposure_px[0]).astype(int)
        rows, columns = np.indices(image.shape[:2])
        distance = np.hypot(columns - x, rows - y)
        ring = (distance > 12) & (distance < 18)
        plain = r.background[..., 2]
        rings[fraction] = float(np.mean(image[..., 2][ring].astype(float) - plain[ring]))
    assert rings[0.0] < 0.5
    assert rings[0.2] > 2.0     # 4.1 grey levels as rendered


def test_the_auto_exposure_gain_walks_within_its_range_and_scales_the_frame(repo: Path
                                                                          ) -> None:
    r = renderer(repo, {"sensor": {"gain_step": 0.05, "gain_range": [0.8, 1.25],
                                   "read_noise": 0.0}}, seconds=2.0)
    assert r.gains.min() >= 0.8 - 1e-9 and r.gains.max() <= 1.25 + 1e-9
    assert np.std(np.diff(np.log(r.gains))) > 0.03
    for index in (0, 30, 59):
        image, truth = r.render(index)
        assert truth.gain == r.gains[index]
        corner = image[:100, :100].astype(float).mean()
        assert corner == pytest.approx(truth.gain * r.background[:100, :100].mean(), rel=0.02)


def test_vignetting_darkens_the_corners_by_its_fraction(repo: Path) -> None:
    r = renderer(repo, {"sensor": {"vignetting": 0.4, "ambient_gradient": 0.0}})
    assert r.falloff is not None
    assert r.falloff[0, 0] == pytest.approx(0.6, abs=0.01)
    assert r.falloff[r.height // 2, r.width // 2] == pytest.approx(1.0, abs=0.01)


def test_glints_come_at_their_rate_and_are_recorded_in_the_truth(repo: Path) -> None:
    r = renderer(repo, {"disturbances": {"glint_rate_per_s": 60.0, "glint_peak": 250.0}},
                 seconds=1.0)
    counts, bright = [], []
    for index in range(30):
        image, truth = r.render(index)
        counts.append(len(truth.glint_px))
        for x, y in np.round(truth.glint_px).astype(int):
            bright.append(int(image[y - 1:y + 2, x - 1:x + 2, 2].max()))
    assert 35 <= sum(counts) <= 90          # Poisson, mean 60: beyond 3 σ otherwise
    assert np.median(bright) > 100


def test_dropouts_of_one_or_two_frames_are_marked_in_the_truth(repo: Path) -> None:
    overrides = draw_imaging(np.random.default_rng(1), ("dropouts",))
    overrides["disturbances"]["occlusion_rate_per_s"] = 1.0
    r = renderer(repo, overrides, seconds=2.0)
    hidden = r.occluded
    assert hidden.any()
    runs = []
    for column in hidden.T:
        edges = np.flatnonzero(np.diff(np.concatenate([[0], column.astype(int), [0]])))
        runs += list(edges[1::2] - edges[::2])
    assert max(runs) <= 4 and min(runs) >= 1   # runs of 1-2 frames, two may touch
    _, truth = r.render(int(np.flatnonzero(hidden.any(axis=1))[0]))
    assert not truth.visible.all()


def test_each_effect_is_drawn_within_its_range_and_alone_as_with_the_others() -> None:
    together = draw_imaging(np.random.default_rng(9))
    for effect in EFFECTS:
        alone = draw_imaging(np.random.default_rng(9), (effect,))
        for section, fields in RANGES[effect].items():
            for name, (low, high) in fields.items():
                assert low <= alone[section][name] <= high
                assert alone[section][name] == together[section][name]
        others = {name for s, f in RANGES.items() if s != effect for fs in f.values()
                  for name in fs}
        assert not others & {name for values in alone.values() for name in values}
