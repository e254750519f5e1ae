"""The tracker against the simulator's truth: accuracy, pixel locking, reflections, occlusions."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy import stats
from scipy.ndimage import gaussian_filter
from sds_camera.frame_source import Region, select
from sds_model.rig import load_rig
from sds_sim.render import FrameRenderer, FrameTruth
from sds_sim.scenario import load_scenario
from sds_tracker.hampel import HampelBank
from sds_tracker.line import LineProfile
from sds_tracker.spots import (
    HAMPEL_REPLACED,
    LOST,
    ON_LINE_SIGMA_PX,
    REACQUIRE_FRAMES,
    REFLECTION_SUSPECTED,
    LineFreeSpot,
    SpotSettings,
    SpotTracker,
    settled_line_free_centre,
    spot_without_line,
)
from sds_tracker.tracker import (
    TRACKING_PARAMETERS,
    FrameTracker,
    TrackedSpot,
    TrackerConfig,
    is_lost,
)
from sds_workflows.calibration_trial import AsBuilt, rig_as_built

from sds_tracker import spots as spots_module


def run_tracker(repo: Path, frames: int, overrides: dict) -> dict:
    """Render a 4K drop, track it, and compare every output with the truth."""
    scenario = load_scenario(repo / "config" / "scenarios" / "ground_kick.yaml",
                             {"duration_s": frames / 30, **overrides})
    renderer, rig = FrameRenderer(scenario), scenario.rig
    x, y, w, h = rig.container_region_px(rig.camera)
    tracker = FrameTracker(rig)
    truths, outputs, line_errors, beyond_rows = {}, [], [], 0.0
    for index in range(frames):
        frame, truth = renderer.render(index)
        truths[index] = truth
        ready, line = tracker.process(index, frame[y:y + h, x:x + w, 2], (x, y))
        outputs += ready
        # The truth's rows are the line's at its rows' times; over the exposure its ends move
        # and light a row or two more (held at the end's column there).
        line_errors += list(line.x_px - np.interp(line.y_px, truth.line_rows, truth.line_x_px))
        beyond_rows = max(beyond_rows, truth.line_rows[0] - line.y_px.min(initial=np.inf),
                          line.y_px.max(initial=-np.inf) - truth.line_rows[-1])
    outputs += tracker.flush()
    ids = [d.laser_id for d in rig.diodes]
    result = {"errors": [], "estimates": [], "truth": [], "fabricated": 0, "wrong": 0,
              "missed": [], "occluded": 0, "frames": sorted(f for f, _ in outputs)}
    for frame, spots in outputs:
        truth = truths[frame]
        for spot in spots:
            i = ids.index(spot.laser_id)
            if not truth.visible[i]:
                result["occluded"] += 1
                result["fabricated"] += not is_lost(spot)
                continue
            if is_lost(spot):
                result["missed"].append((frame, spot.laser_id))
                continue
            error = np.array([spot.x_px, spot.y_px]) - truth.spot_exposure_px[i]
            raw_error = np.array([spot.x_raw_px, spot.y_raw_px]) - truth.spot_exposure_px[i]
            if np.linalg.norm(raw_error) > 1.0:   # another spot or a reflection taken
                result["wrong"] += 1
            if np.linalg.norm(error) > 1.0 and not spot.flags & HAMPEL_REPLACED:
                result["wrong"] += 1
            result["errors"].append(error)
            result["estimates"].append([spot.x_px, spot.y_px])
            result["truth"].append(truth.spot_exposure_px[i])
    result["line_errors"], result["line_beyond_rows"] = np.array(line_errors), beyond_rows
    for key in ("errors", "estimates", "truth"):
        result[key] = np.array(result[key])
    return result


@pytest.fixture(scope="module")
def default_drop(repo: Path) -> dict:
    return run_tracker(repo, 60, {})


def test_spots_are_accurate_at_the_default_noise(default_drop: dict) -> None:
    errors = default_drop["errors"]
    assert len(errors) > 1100 and default_drop["frames"] == list(range(60))
    assert np.sqrt(np.mean(errors**2)) <= 0.05
    assert default_drop["wrong"] == 0 and default_drop["fabricated"] == 0


def test_no_pixel_locking(default_drop: dict) -> None:
    estimated = (default_drop["estimates"] % 1).ravel()
    true = (default_drop["truth"] % 1).ravel()
    # The estimates' fractional parts spread like the truth's...
    assert stats.ks_2samp(estimated, true).pvalue > 0.01
    # ...and the error does not depend on where in its pixel the spot sits.
    phase = np.exp(2j * np.pi * true)
    assert 2 * abs(np.mean(default_drop["errors"].ravel() * phase)) < 0.01


def test_line_centre_is_accurate(default_drop: dict) -> None:
    line = default_drop["line_errors"]
    assert len(line) > 60 * 900
    assert np.sqrt(np.mean(line**2)) <= 0.1
    # Nothing beyond the line's ends but the rows they pass in an exposure (2 in this drop).
    assert default_drop["line_beyond_rows"] <= 2


def test_reflections_and_occlusions_give_no_swaps_and_no_inventions(repo: Path) -> None:
    result = run_tracker(repo, 60, {
        "disturbances": {"reflection_strength": 0.5, "occlusion_rate_per_s": 0.8},
        "modes": [{"order": 1, "index": 1, "amplitude_mm": 8.0, "damping_ratio": 0.01},
                  {"order": 1, "index": 2, "amplitude_mm": 2.0, "damping_ratio": 0.01}]})
    assert result["occluded"] > 30
    assert result["fabricated"] == 0          # every occlusion reported lost
    assert result["wrong"] == 0               # no reflection or neighbour taken for a spot
    assert result["missed"] == []             # found again on the first visible frame
    assert np.sqrt(np.mean(result["errors"] ** 2)) <= 0.06


def test_hampel_keeps_a_fast_spot_and_replaces_a_reflection() -> None:
    t = np.arange(60)
    track = np.column_stack([25 * np.sin(2 * np.pi * 2.8 * t / 30), 8 * np.cos(t / 5)])
    corrupted = track.copy()
    corrupted[20] += [6.0, -4.0]        # a reflection for one frame
    corrupted[41] += [0.0, 3.0]
    corrupted[33] = np.nan              # an occlusion
    corrupted[58] += [6.0, 0.0]         # next to the end: no two-sided window, kept
    hampel = HampelBank(window=5)   # one track: 1×2 positions per frame
    outputs = [o for i, p in enumerate(corrupted) if (o := hampel.push(i, p[None])) is not None]
    outputs += hampel.flush()
    assert [o.frame for o in outputs] == list(range(60))
    replaced = {o.frame for o in outputs if o.replaced[0]}
    assert replaced == {20, 41}
    assert np.isnan(outputs[33].filtered).all()
    assert not outputs[58].replaced[0] and not outputs[59].replaced[0]
    for frame in (20, 41):
        assert np.linalg.norm(outputs[frame].filtered[0] - track[frame]) < 0.5
    with pytest.raises(ValueError, match="odd"):
        HampelBank(window=4)


def test_hampel_keeps_a_deviation_within_the_spots_own_sigma() -> None:
    """A 3 px jump is a reflection for a spot measured to 0.05 px, and within the noise of
    one measured to 1.5 px: only the first is replaced."""
    t = np.arange(20.0)
    track = np.column_stack([0.5 * t, np.zeros_like(t)])
    track[10] += [3.0, 0.0]
    for sigma_px, replaced in ((0.05, True), (1.5, False)):
        hampel = HampelBank(window=5)
        outputs = [o for i, p in enumerate(track)
                   if (o := hampel.push(i, p[None], np.array([sigma_px]))) is not None]
        assert {o.frame for o in outputs if o.replaced[0]} == ({10} if replaced else set())


def test_stills_of_different_surfaces_are_tracked_each_on_its_own(repo: Path) -> None:
    """Tilt-table images are no video: with `stills` every image's spots come out with it,
    none replaced by a temporal filter, each where its image shows it."""
    from sds_sim.tilt_series import render_tilt_series

    rig = load_rig(repo / "config" / "rigs" / "stelium.yaml")
    series = render_tilt_series(rig, [0.0, 35.0, 0.0, 35.0, 0.0, 35.0], "x", seed=4)
    x, y, w, h = rig.container_region_px(rig.camera, 60)
    tracker = FrameTracker(rig, TrackerConfig(stills=True))
    errors = []
    for index, (image, truth) in enumerate(zip(series.images, series.truths, strict=True)):
        ready, _ = tracker.process(index, image[y:y + h, x:x + w, 2], (x, y))
        assert [frame for frame, _ in ready] == [index]     # no latency
        for spot in ready[0][1]:
            assert not spot.flags & HAMPEL_REPLACED
            np.testing.assert_equal((spot.x_px, spot.y_px), (spot.x_raw_px, spot.y_raw_px))
            k = [d.laser_id for d in rig.diodes].index(spot.laser_id)
            if truth.visible[k] and not is_lost(spot):
                errors.append(np.hypot(spot.x_px - truth.spot_exposure_px[k, 0],
                                       spot.y_px - truth.spot_exposure_px[k, 1]))
    assert tracker.flush() == []
    assert len(errors) >= 100 and np.percentile(errors, 95) < 0.3


def test_the_line_on_a_tilted_still_is_found_along_its_whole_length(repo: Path) -> None:
    """On a still of a tilted surface the line lies far off the level surface's line, beyond
    the band searched around it: it is sought over its whole reach, found on nearly all its
    rows, and no spot it passes is measured against a wrong line (one such spot read 3 px off
    with σ 0.08 px, and a tilt 0.3° off)."""
    from sds_recon.calibration.plan import diagonal
    from sds_sim.tilt_series import render_surfaces

    rig = load_rig(repo / "config" / "rigs" / "stelium.yaml")
    surfaces = [diagonal(35.0), diagonal(0.0), diagonal(-25.0), diagonal(20.0)]
    series = render_surfaces(rig, surfaces, seed=8)
    x, y, w, h = rig.container_region_px(rig.camera, 60)
    tracker = FrameTracker(rig, TrackerConfig(stills=True))
    spot_errors = []
    for index, (image, truth) in enumerate(zip(series.images, series.truths, strict=True)):
        ready, line = tracker.process(index, image[y:y + h, x:x + w, 2], (x, y))
        assert set(line.y_px) <= set(truth.line_rows), index   # nothing beyond its ends
        true_x = np.interp(line.y_px, truth.line_rows, truth.line_x_px)
        assert np.max(np.abs(line.x_px - true_x)) < 0.5, index
        assert len(line.y_px) >= 0.9 * len(truth.line_rows), index
        for spot in ready[0][1]:
            k = [d.laser_id for d in rig.diodes].index(spot.laser_id)
            low_mm, high_mm = tracker.config.path_heights_mm   # where the paths reach
            if truth.visible[k] and low_mm <= truth.spot_mm[k, 2] <= high_mm:
                assert not is_lost(spot), (index, spot.laser_id)
                spot_errors.append(np.hypot(spot.x_px - truth.spot_exposure_px[k, 0],
                                            spot.y_px - truth.spot_exposure_px[k, 1]))
    assert len(spot_errors) >= 70 and max(spot_errors) < 0.5, max(spot_errors)


def test_a_rig_without_a_line_laser_is_tracked(repo: Path) -> None:
    """A rig without a line laser (its drop rendered without one) has no line to seek or to
    take away: every frame's line is empty and every visible spot is measured, within 0.5 px
    of its truth (a version that sought the line beyond the level surface's rows failed on
    the first frame)."""
    scenario = load_scenario(repo / "config" / "scenarios" / "ground_kick.yaml",
                             {"duration_s": 0.4, "scale": 0.5})
    rig = replace(scenario.rig, line_laser=None)
    renderer = FrameRenderer(replace(scenario, rig=rig))
    tracker = FrameTracker(replace(rig, camera=rig.camera.scaled(0.5)))
    truths, outputs = {}, []
    for index in range(12):
        image, truths[index] = renderer.render(index)
        ready, line = tracker.process(index, image[..., 2], (0, 0))
        assert len(line.x_px) == 0
        outputs += ready
    outputs += tracker.flush()
    ids = [d.laser_id for d in rig.diodes]
    assert len(outputs) == 12
    for index, spots in outputs:
        found = errors_px(spots, truths[index], ids)
        assert len(found) == int(truths[index].visible.sum()), index
        assert max(error_px for _, error_px, _ in found) < 0.5, index


def test_manual_seeds_start_the_spots_and_bad_seeds_are_refused(repo: Path) -> None:
    scenario = load_scenario(repo / "config" / "scenarios" / "ground_kick.yaml",
                             {"duration_s": 0.2})
    frame, truth = FrameRenderer(scenario).render(0)
    rig = scenario.rig
    x, y, w, h = rig.container_region_px(rig.camera)
    seeds = {d.laser_id: tuple(p + 3.0) for d, p in zip(rig.diodes, truth.spot_px, strict=True)}
    tracker = FrameTracker(rig, seeds=seeds)
    assert all(tracker.spots.previous[i] is not None for i in seeds)
    estimates = tracker.spots.update(frame[y:y + h, x:x + w, 2], (x, y))
    found = np.array([[e.x_px, e.y_px] for e in estimates])
    assert np.max(np.abs(found - truth.spot_px)) < 0.3
    with pytest.raises(ValueError, match="laser 99"):
        FrameTracker(rig, seeds={99: (10.0, 10.0)})


def test_the_line_is_subtracted_from_a_spot_beside_it() -> None:
    """A spot 4 px beside the laser line: its centre without the line's light."""
    settings = SpotSettings()
    size = 2 * settings.window_px + 1
    rows, columns = np.mgrid[0:size, 0:size].astype(float)
    spot = np.array([26.3, 23.6])                                  # x, y [window px]
    line_x = 30.4 + 0.05 * (rows[:, 0] - 24)                      # a slightly slanted line
    line = 90.0 * np.exp(-0.5 * ((columns - line_x[:, None]) / 1.5) ** 2)
    light = 20.0 + line + 150.0 * np.exp(-0.5 * ((columns - spot[0]) ** 2 +
                                                 (rows - spot[1]) ** 2) / 2.0**2)
    plain = np.array([np.sum(light * columns), np.sum(light * rows)]) / np.sum(light)
    assert np.hypot(*(plain - spot)) > 0.5                         # the line pulls it
    found = spot_without_line(light, line_x, spot + np.array([1.5, -1.0]), settings)
    assert found is not None and np.hypot(*(found.centre - spot)) < 0.1


def spot_on_background(spot: np.ndarray, background: np.ndarray, seed: int) -> np.ndarray:
    """A saturated 4K-sized spot (x, y) on a background image, with shot and read noise."""
    rows, columns = np.indices(background.shape)
    light = background + 600.0 * np.exp(-0.5 * ((columns - spot[0]) ** 2 +
                                               (rows - spot[1]) ** 2) / 5.0**2)
    noise = np.random.default_rng(seed).normal(0.0, 1.0, light.shape) * np.sqrt(light + 4.0)
    return np.clip(np.round(light + noise), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_spot_on_the_rims_edge_reports_the_error_the_edge_gives_it(seed: int) -> None:
    """A spot at the container's rim in the image (the liquid dark, beyond the rim 12 grey
    levels brighter): a scalar background leaves the edge in its light, which pulls it by
    tenths of a pixel, far beyond its photons' σ. Its σ says so, in the tracker's steady state
    and its full search alike; on one level, or with the laser line along its window's side,
    the σ is the photons' alone."""
    settings = SpotSettings()
    size = 120
    rows, columns = np.indices((size, size))
    spot = np.array([60.3, 59.6])
    flat = np.full((size, size), 8.0)
    edge = np.where(columns + 0.4 * rows > spot[0] + 0.4 * spot[1] + 1.0, 20.0, 8.0)
    line = flat + 60.0 * np.exp(-0.5 * ((columns - (spot[0] - settings.window_px)) / 1.5) ** 2)
    along = np.array([0.0, 40.0])
    path = np.array([spot - along, spot + along])
    sigmas = {}
    for name, background in (("flat", flat), ("edge", edge), ("line", line)):
        image = spot_on_background(spot, background, seed)
        for mode in ("steady", "search"):
            tracker = SpotTracker({0: path}, settings)
            tracker.previous[0] = spot + np.array([0.4, -0.3]) if mode == "steady" else None
            (estimate,) = tracker.update(image)
            error = np.hypot(estimate.x_px - spot[0], estimate.y_px - spot[1])
            sigmas[name, mode] = estimate.sigma_px
            assert error < 3 * estimate.sigma_px, (name, mode, error, estimate.sigma_px)
    assert sigmas["flat", "steady"] < 0.1
    for mode in ("steady", "search"):
        assert sigmas["edge", mode] > 3 * sigmas["flat", mode]
        assert sigmas["line", mode] < 1.1 * sigmas["flat", mode]


def saturated_spot_and_line(spot: np.ndarray, line_x: np.ndarray, size: int,
                            line_sigma_px: float = 1.8, line_peak: float = 400.0,
                            spot_peak: float = 900.0, spot_sigma_px: float = 3.0
                            ) -> np.ndarray:
    """A window where a bright spot (x, y) and a bright slanted line (centre column
    `line_x[row]`) both clip at 255."""
    rows, columns = np.mgrid[0:size, 0:size].astype(float)
    line = line_peak * np.exp(-0.5 * ((columns - line_x[:, None]) / line_sigma_px) ** 2)
    light = 8.0 + line + spot_peak * np.exp(-0.5 * ((columns - spot[0]) ** 2 +
                                                    (rows - spot[1]) ** 2) / spot_sigma_px**2)
    return np.minimum(np.round(light), 255.0).astype(np.float32)


@pytest.mark.parametrize("beside_px", [1.5, 3.0, 6.0, 9.0])
def test_a_spot_overlapping_a_saturated_line_is_measured_by_its_symmetry(beside_px: float
                                                                          ) -> None:
    """Where spot and line both saturate, the spot's light on the line is unknown: taking
    the saturated pixels as the spot's pulls it towards the line; the spot's symmetry does
    not (taking them pulls it 0.6–3.8 px here). The line's direction comes back, and the two
    are reported as overlapping."""
    settings = SpotSettings()
    size = 2 * settings.window_px + 1
    line_x = 24.3 + 0.1 * (np.arange(size) - 24)
    along = np.array([0.1, 1.0]) / np.hypot(0.1, 1.0)
    spot = np.array([24.3 - beside_px * along[1], 23.6 + beside_px * along[0]])
    window = saturated_spot_and_line(spot, line_x, size)
    found = spot_without_line(window, line_x, np.round(spot), settings)
    assert found is not None and np.hypot(*(found.centre - spot)) < 0.2, found
    assert abs(found.along @ along) > 0.999
    assert found.clearance_px < 0


@pytest.mark.parametrize(("line_sigma_px", "line_peak", "spot_peak"),
                         [(1.5, 600.0, 900.0), (1.5, 600.0, 1500.0), (1.8, 400.0, 900.0)])
def test_a_spot_whose_mirror_half_a_saturated_line_hides_is_not_measured(
        line_sigma_px: float, line_peak: float, spot_peak: float) -> None:
    """A small saturated spot (σ 2 px, a 4K spot at half scale) centred 2 px beside a
    saturated line, within the line's band and not reaching across it: the mirror image of
    its visible half lies under the line, so its own centre has too few mirrored pairs and
    the best centre that has enough was 2.7-2.8 px off, away from the line, and valid (the
    real-images bench's held-out rig 61117: 3.5 px off). Its centre is not known: no spot
    is measured there."""
    settings = SpotSettings()
    size = 2 * settings.window_px + 1
    line_x = np.full(size, 24.3)
    spot = np.array([26.3, 23.6])
    window = saturated_spot_and_line(spot, line_x, size, line_sigma_px, line_peak, spot_peak,
                                     spot_sigma_px=2.0)
    found = spot_without_line(window, line_x, np.round(spot), settings)
    assert found is not None and not np.isfinite(found.centre).any(), found
    image = np.zeros((200, 200), np.uint8)
    image[76:125, 76:125] = window.astype(np.uint8)
    image[:76] = image[76]
    image[125:] = image[124]
    tracker = SpotTracker({0: spot + 76.0 + np.array([[0.0, -40.0], [0.0, 40.0]])}, settings)
    tracker.previous[0] = spot + 76.0 + np.array([0.3, 0.3])
    (estimate,) = tracker.update(image, (0, 0), (np.arange(200.0), np.full(200, 100.3)))
    assert estimate.flags & LOST, estimate


def test_the_tracker_takes_the_lines_light_out_of_a_spot_it_overlaps() -> None:
    """A spot 6 px beside a saturated line, the line's light pulling its plain centroid along
    its path (so the path cannot tell), another spot 18 px away: tracked with the line, it is
    measured with the line's light taken away and carries the σ of such spots."""
    settings = SpotSettings()
    size = 160
    line_x = np.full(size, 80.3)
    spot = np.array([74.3, 81.6])
    rows, columns = np.mgrid[0:size, 0:size]
    neighbour = 900.0 * np.exp(-0.5 * ((columns - 56.3) ** 2 + (rows - 83.0) ** 2) / 3.0**2)
    image = np.minimum(saturated_spot_and_line(spot, line_x, size) + neighbour,
                       255).astype(np.uint8)
    step = np.array([40.0, 0.0])
    path = np.array([spot - step, spot + step])
    tracker = SpotTracker({0: path}, settings)
    tracker.previous[0] = spot + np.array([1.0, 0.5])
    (estimate,) = tracker.update(image, (0, 0), (np.arange(size), line_x))
    assert np.hypot(estimate.x_px - spot[0], estimate.y_px - spot[1]) < 0.2, estimate
    assert estimate.sigma_px >= ON_LINE_SIGMA_PX[1]
    tracker.previous[0] = spot + np.array([1.0, 0.5])
    (plain,) = tracker.update(image, (0, 0))
    # Without the line the spot is not found where it is: its blob is the line's, and the
    # neighbour 18 px away is beyond where the spot can have moved in a frame (lost).
    assert plain.flags & LOST or np.hypot(plain.x_px - spot[0], plain.y_px - spot[1]) > 0.5


@pytest.mark.parametrize("last_seen", [(76.0, 81.0), (80.0, 81.0), None])
def test_a_spot_gone_where_its_path_crosses_the_line_is_lost_not_put_on_the_line(
        last_seen: tuple[float, float] | None) -> None:
    """The line's light alone is a blob on the spot's path: it is no spot."""
    size = 160
    line_x = 80.3 + 0.05 * (np.arange(size) - 80)
    noise = np.random.default_rng(1).normal(0, 3, (size, size))
    image = np.clip(saturated_spot_and_line(np.array([-100.0, -100.0]), line_x, size) + noise,
                    0, 255).astype(np.uint8)
    path = np.array([[36.0, 81.0], [116.0, 81.0]])
    tracker = SpotTracker({0: path}, SpotSettings())
    tracker.previous[0] = None if last_seen is None else np.array(last_seen)
    (estimate,) = tracker.update(image, (0, 0), (np.arange(size), line_x))
    assert estimate.flags & LOST and np.isnan(estimate.x_px)


@pytest.mark.parametrize("with_spot", [True, False])
def test_a_spot_on_the_line_is_acquired_where_its_path_runs_beside_the_line(
        with_spot: bool) -> None:
    """Seed 29's drop: the path runs 1-8 px beside the laser line for 190 px, and the spot
    overlaps the line when it is first searched for: spot and line are one blob, centred on
    the line. It is acquired, measured without the line's light, from starts along the path;
    where there is no spot, nothing is."""
    settings = SpotSettings()
    size = 200
    line_x = 100.3 + 0.02 * (np.arange(size) - 100)
    spot = np.array([105.0, 120.4]) if with_spot else np.array([-100.0, -100.0])
    # Read noise before the sensor clips: a saturated pixel reads 255.
    clean = saturated_spot_and_line(spot, line_x, size)
    noise = np.random.default_rng(2).normal(0, 3, (size, size))
    image = np.where(clean >= 255, 255, np.clip(clean + noise, 0, 254)).astype(np.uint8)
    path = np.array([[106.0, 20.0], [104.0, 180.0]])
    tracker = SpotTracker({0: path}, settings)
    (estimate,) = tracker.update(image, (0, 0), (np.arange(size), line_x))
    if not with_spot:
        assert estimate.flags & LOST and np.isnan(estimate.x_px)
        return
    assert not estimate.flags & LOST, estimate
    assert np.hypot(estimate.x_px - spot[0], estimate.y_px - spot[1]) < 0.2, estimate
    assert estimate.sigma_px >= ON_LINE_SIGMA_PX[1]


def test_a_spot_whose_light_merges_with_the_lines_is_acquired_in_the_first_frame(
        repo: Path) -> None:
    """Held-out rig 9111's drop: in the first frame, diode 18's spot lies 12.7 px beside the
    laser line and their light is one blob above the threshold, centred 15 px from the spot.
    Measured without the line's light from there, nothing was left; the search along its path
    then found the spot clear of the line, where it took only spots that overlap the line, so
    the spot was lost. Every visible spot is found in the first frame, where it is."""
    _, true = rig_as_built(load_rig(repo / "config" / "rigs" / "stelium.yaml"), AsBuilt(),
                           np.random.default_rng(9111))
    scenario = load_scenario(repo / "config" / "scenarios" / "ground_kick.yaml",
                             {"seed": 9111})
    scenario = replace(scenario, rig=true, disturbances=replace(scenario.disturbances,
                                                                occlusion_rate_per_s=0.0))
    image, truth = FrameRenderer(scenario).render(round(scenario.kick_s * scenario.fps))
    region = Region(*true.container_region_px(true.camera, 60))
    tracker = FrameTracker(true)
    tracker.process(0, select(image, region, "red"), (region.x, region.y))
    ((_, spots),) = tracker.flush()
    ids = [d.laser_id for d in true.diodes]
    visible = {ids[i] for i in np.flatnonzero(truth.visible)}
    assert 18 in visible
    for spot in spots:
        if spot.laser_id in visible:
            assert not is_lost(spot), spot
            expected = truth.spot_exposure_px[ids.index(spot.laser_id)]
            assert np.hypot(spot.x_raw_px - expected[0], spot.y_raw_px - expected[1]) < 0.3


def line_frame(seed: int, spot: np.ndarray | tuple[float, float] | None, line_x: np.ndarray,
               line_peak: np.ndarray | float, speckle: float, size: int = 200) -> np.ndarray:
    """A frame with a laser line (its centre column `line_x` and peak `line_peak` on each row,
    σ 1.8 px) whose light varies `speckle` from pixel to pixel, read noise, and optionally a
    saturating spot (x, y)."""
    rows, columns = np.mgrid[0:size, 0:size].astype(float)
    rng = np.random.default_rng(seed)
    peak = np.broadcast_to(np.asarray(line_peak, dtype=float), (size,))
    light = 8.0 + peak[:, None] * rng.normal(1.0, speckle, (size, size)) * np.exp(
        -0.5 * ((columns - line_x[:, None]) / 1.8) ** 2)
    if spot is not None:
        light += 900.0 * np.exp(-0.5 * ((columns - spot[0]) ** 2 + (rows - spot[1]) ** 2)
                                / 3.0**2)
    noisy = np.round(light + rng.normal(0, 2, (size, size)))
    return np.clip(noisy, 0, 255).astype(np.uint8)


def speckled_line_frame(seed: int, spot: np.ndarray | None, size: int = 200
                        ) -> tuple[np.ndarray, np.ndarray]:
    """A frame with an unsaturated laser line whose light varies 20 % from pixel to pixel
    (speckle), read noise, and optionally a saturating spot; and the line's columns."""
    line_x = 100.3 + 0.02 * (np.arange(size) - 100)
    return line_frame(seed, spot, line_x, 230.0, 0.2, size), line_x


@pytest.mark.parametrize("seed", range(5))
def test_the_lines_speckle_is_no_spot_and_hides_none(seed: int) -> None:
    """What the line's speckle leaves once its mean profile is taken away (up to 5 σ of it on
    a 4K drop) is no spot; a spot beside the line, along whose path the line runs, is still
    acquired. (Taking any light above the threshold for a spot, the tracker put a spot on
    the bare line in 10 of 20 such frames and missed the real one in 9 of 10.)"""
    path = np.array([[104.0, 20.0], [102.0, 180.0]])
    for spot in (None, np.array([104.5, 120.4])):
        image, line_x = speckled_line_frame(seed, spot)
        tracker = SpotTracker({0: path}, SpotSettings())
        (estimate,) = tracker.update(image, (0, 0), (np.arange(200.0), line_x))
        if spot is None:
            assert estimate.flags & LOST, estimate
        else:
            assert np.hypot(estimate.x_px - spot[0], estimate.y_px - spot[1]) < 0.5, estimate


def wide_spot_on_a_speckled_line(spot: np.ndarray, line_x: np.ndarray, size: int,
                                 seed: int) -> np.ndarray:
    """A window where a wide saturated spot (σ 4.5 px, peak 2500: some 13 px in radius above
    the threshold, as in a high fill level's 4K stills) lies on a saturated line (σ 2 px),
    both with speckle of 30 % and shot and read noise."""
    rng = np.random.default_rng(seed)
    rows, columns = np.mgrid[0:size, 0:size].astype(float)
    line = 600.0 * np.exp(-0.5 * ((columns - line_x[:, None]) / 2.0) ** 2)
    light = 2500.0 * np.exp(-0.5 * ((columns - spot[0]) ** 2 + (rows - spot[1]) ** 2) / 4.5**2)
    light = 15.0 + (line + light) * np.clip(rng.normal(1.0, 0.3, light.shape), 0.0, None)
    noisy = light + rng.normal(0.0, 1.0, light.shape) * np.sqrt(light + 4.0)
    return np.clip(np.round(noisy), 0, 255).astype(np.float32)


@pytest.mark.parametrize("seed", range(6))
def test_a_wide_saturated_spot_on_the_line_is_centred_on_its_whole_light(seed: int) -> None:
    """The development stills of 7101-7116, high fill level: saturated spots some 24 px
    across on the saturated line were measured 2.4-4.2 px off (σ 0.13 px), the search for
    their centre of symmetry judging only half a window about each centre it tried. Here
    such a spot 1-3 px beside the line is found within 1 px (twelve draws: 0.05-0.49 px;
    with half a window, 4.1-5.1 px off in 6 of them, 3 of the 6 below)."""
    settings = SpotSettings()
    size = 2 * settings.window_px + 1
    rng = np.random.default_rng(100 + seed)
    line_x = 24.0 + rng.uniform(-0.5, 0.5) + 0.03 * (np.arange(size) - 24.0)
    spot = np.array([line_x[24] + rng.choice([-1.0, 1.0]) * rng.uniform(1.0, 3.0),
                     24.0 + rng.uniform(-0.5, 0.5)])
    found = spot_without_line(wide_spot_on_a_speckled_line(spot, line_x, size, seed), line_x,
                              np.round(spot) + rng.uniform(-1.0, 1.0, 2), settings)
    assert found is not None and np.hypot(*(found.centre - spot)) < 1.0, found


def test_a_spot_clear_of_the_line_is_reported_clear() -> None:
    settings = SpotSettings()
    size = 2 * settings.window_px + 1
    line_x = np.full(size, 40.0)
    spot = np.array([20.4, 24.2])
    found = spot_without_line(saturated_spot_and_line(spot, line_x, size), line_x,
                                   spot, settings)
    assert found is not None and np.hypot(*(found.centre - spot)) < 0.1
    assert found.clearance_px > 0


def test_a_video_spot_clear_of_the_line_keeps_its_centroid() -> None:
    """A speckled saturating spot tracked in a fixed aperture, the laser line 18 px beside it
    (within the compiled pass's window, so the full search measures it, and within reach of
    the line-free measurement): the line's light lies beyond the aperture, and the spot is
    measured as without the line, by its centroid. Its centre of symmetry with the line's
    light taken away was given before: 0.35 px RMS off against the centroid's 0.23, 0.43 px
    from it at the most (development rigs' codec videos: a clear spot so measured was 0.11
    px off at the median, its centroid 0.04)."""
    size = 200
    rows, columns = np.mgrid[0:size, 0:size].astype(float)
    path = np.array([[100.0, 40.0], [100.0, 160.0]])
    line = (np.arange(size, dtype=float), np.full(size, 118.0))
    for seed in range(10):
        rng = np.random.default_rng(seed)
        spot = np.array([100.0, 100.0]) + rng.uniform(-0.5, 0.5, 2)
        spot_light = 400.0 * np.exp(-0.5 * ((columns - spot[0]) ** 2 + (rows - spot[1]) ** 2)
                                    / 2.0**2)
        line_light = 200.0 * np.exp(-0.5 * ((columns - line[1][:, None]) / 1.8) ** 2)
        pattern = speckle_pattern(rng, (size, size), 0.5, 1.0)
        noise = rng.normal(size=(size, size))
        found = []
        for lit, light in ((None, 10.0 + spot_light * pattern),
                           (line, 10.0 + (spot_light + line_light) * pattern)):
            image = np.clip(np.round(light + noise * np.sqrt(light + 4)), 0, 255)
            tracker = SpotTracker({0: path}, apertures_px={0: 6.0})
            tracker.previous[0] = spot + 0.3
            (estimate,) = tracker.update(image.astype(np.uint8), (0, 0), lit)
            assert not estimate.flags & LOST, (seed, estimate)
            found.append(np.array([estimate.x_px, estimate.y_px]))
        assert np.hypot(*(found[1] - found[0])) < 0.02, (seed, found)


def test_a_spot_acquired_beside_the_line_keeps_its_line_free_centre(repo: Path) -> None:
    """The held-out real-images rig 73109 (speckle at contrast and grain drawn for its seed):
    diode 16, 6 px beside the laser line, was lost in frame 10 and acquired again in frame 11.
    Its centre without the line's light was right and put the line's edge just beyond the
    aperture, so its centroid was kept, but that centroid, started between the spot and the
    line whose light merged with it, had been pulled 3.6 px towards the line (valid, σ 0.13
    px). The line's edge must lie beyond the aperture about the centroid itself: every spot
    measured in the first 12 frames is within 2 px of its truth, and at least 95 % of the
    visible ones are measured (all 240 here)."""
    from sds_sim.imaging import draw_imaging, merged

    seed = 73109
    imaging = draw_imaging(np.random.default_rng(seed), ("speckle",))
    ids, truths, outputs = track_a_rendered_rig_as_built(
        repo, seed, merged({"duration_s": 0.4}, imaging), 12)
    measured = 0
    for index, spots in outputs:
        for spot, error_px, visible in errors_px(spots, truths[index], ids):
            if visible:
                measured += 1
                assert error_px < 2.0, (index, spot)
    assert measured >= 228


def test_a_spot_beside_the_lines_end_beyond_the_flat_lines_rows_keeps_none_of_its_light(
        tmp_path: Path) -> None:
    """The held-out stills rig 74001, its still before the high fill level's: the line runs
    22 rows beyond the flat surface's line's top end, and diode 3's saturated spot lies 10 px
    beside it, 16 rows beyond the line's end. The line was sought on the flat line's rows
    only, so the spot's window held none of it and the spot's centroid took in the line's
    end: 2.1 px off, σ 0.05 px, valid. Sought on every row it can cross, the line is found
    to its end and taken away from the spot: the spot is within 3 of its σ, and every other
    measured spot within 2 px."""
    ids, spots, line, truth = tracked_demo_still(74001, 10, tmp_path)
    assert line.y_px.min() <= truth.line_rows[0] + 2
    errors = {spot.laser_id: (spot, error_px)
              for spot, error_px, visible in errors_px(spots, truth, ids) if visible}
    spot, error_px = errors.pop(3)
    assert error_px <= 3 * spot.sigma_px, spot
    assert max(error for _, error in errors.values()) < 2.0


def test_a_saturated_spot_whose_far_side_the_saturated_line_hides_is_not_measured(
        tmp_path: Path) -> None:
    """The held-out stills rig 76020, its still before the high fill level's: diode 18's
    saturated, blooming spot lies 4-6 px from the saturated laser line, whose band hides its
    far side. Its centre of symmetry slid 2.3 px across the line with σ 0.13 px, valid. The
    symmetry's mismatch rises only 5 % over 1.5 px towards the truth (`symmetry_spreads`),
    below HIDDEN_CENTRE_RISE, so it is not measured; the 13 other spots measured before
    still are, each within 2 px."""
    ids, spots, _, truth = tracked_demo_still(76020, 10, tmp_path)
    errors = {spot.laser_id: (spot, error_px)
              for spot, error_px, visible in errors_px(spots, truth, ids) if visible}
    assert truth.visible[ids.index(18)]
    assert 18 not in errors, errors.get(18)
    assert len(errors) >= 13   # every other spot the code before measured here
    assert max(error for _, error in errors.values()) < 2.0


def test_a_stripe_whose_light_a_spot_beside_it_rounds_is_no_spot(tmp_path: Path) -> None:
    """The held-out stills rig 77019, its third still: ambient light lights the container's
    rim as a thin stripe, which passes 3-6 px from diode 6's saturated spot. The stripe's blob
    (about 1100 px) outweighs the spot's and its centroid lies on the path; its brightest
    pixel is beside the spot, so within half a window all the light there is round. Its
    clipped centroid, 30 px wide, took the spot in and landed 3.3 px off, valid. The stripe's
    own light alone is elongated (`own_light`): the spot's blob is measured, within 3 of its
    σ, and every other spot within 2 px."""
    ids, spots, _, truth = tracked_demo_still(77019, 2, tmp_path)
    errors = {spot.laser_id: (spot, error_px)
              for spot, error_px, visible in errors_px(spots, truth, ids) if visible}
    spot, error_px = errors.pop(6)
    assert error_px <= 3 * spot.sigma_px, spot
    assert max(error for _, error in errors.values()) < 2.0


def test_a_spot_at_the_lines_own_end_keeps_its_light_past_that_end(tmp_path: Path) -> None:
    """The held-out stills rig 78012, its ninth still (tilted): the line ends at row 1505,
    above the level surface's line's end, and diode 8's saturated spot lies on it 7 rows
    above its end. The line's light was taken from the rows past its end too, where it has
    none, and the spot's centre slid 2.75 px across the line, valid. The rows past that end
    are dark (`line.end_is_dark`), so the line is taken away only where it is, and its fading
    end rows are not read as the line bending (LINE_END_FADING_ROWS): the spot is within 3
    of its σ, and every other spot within 2 px."""
    ids, spots, line, truth = tracked_demo_still(78012, 8, tmp_path)
    assert line.y_px.max() <= truth.line_rows[-1] + 3
    errors = {spot.laser_id: (spot, error_px)
              for spot, error_px, visible in errors_px(spots, truth, ids) if visible}
    spot, error_px = errors.pop(8)
    assert error_px <= 3 * spot.sigma_px, spot
    assert max(error for _, error in errors.values()) < 2.0


def tracked_demo_still(seed: int, still: int, folder: Path
                       ) -> tuple[list[int], list[TrackedSpot], LineProfile, FrameTruth]:
    """One still of a demo rig's protocol (`draw_demo_rig` of `seed`, its imaging), rendered
    as the stills bench renders it and tracked with the true rig: the diodes' ids, the
    spots, the line and the still's truth."""
    from sds_sim.tilt_series import render_surfaces
    from sds_workflows.demo import DEMO_SCENARIO
    from sds_workflows.demo_rig import draw_demo_rig

    drawn = draw_demo_rig(load_scenario(DEMO_SCENARIO, {"seed": seed}), folder)
    series = render_surfaces(drawn.true, [drawn.surfaces[still]], drawn.scale,
                             drawn.seed + still, imaging=drawn.imaging)
    rig = drawn.true
    region = Region(*rig.container_region_px(rig.camera, 60))
    ((_, spots),), line = FrameTracker(rig, TrackerConfig(stills=True)).process(
        0, select(series.images[0], region, "red"), (region.x, region.y))
    return [d.laser_id for d in rig.diodes], spots, line, series.truths[0]


def test_the_parameter_file_states_the_trackers_own_defaults(repo: Path) -> None:
    """config/params/tracker.yaml documents every tracking parameter with the value the code
    defaults to (TrackerConfig and its settings): the two cannot drift apart."""
    document = yaml.safe_load((repo / "config" / "params" / "tracker.yaml").read_text())
    documented = document["/**"]["ros__parameters"]
    for name, value in TRACKING_PARAMETERS.items():
        assert documented[name] == value, name


def test_a_weakly_calibrated_beam_widens_its_own_path_gate_only(repo: Path) -> None:
    """A beam whose direction the calibration left at σ 0.3° (tilts about one axis only) is
    0.5° off; at 35° about the other axis its spot lies beyond the 4 px gate: with the σ in
    the rig file the tracker widens that beam's gate and finds it, and no other gate moves."""
    from scipy.spatial.transform import Rotation
    from sds_sim.tilt_series import render_tilt_series
    from sds_tracker.spots import OFF_PATH

    rig = load_rig(repo / "config" / "rigs" / "stelium.yaml")
    leaning = Rotation.from_euler("x", 0.5, degrees=True).apply(rig.diodes[0].direction)
    true = replace(rig, diodes=(replace(rig.diodes[0], direction=leaning), *rig.diodes[1:]))
    series = render_tilt_series(true, [35.0], "y", seed=6)
    x, y, w, h = rig.container_region_px(rig.camera, 60)
    red = series.images[0][y:y + h, x:x + w, 2]
    truth_px = series.truths[0].spot_exposure_px[0]

    def spot_zero(file_rig):
        tracker = FrameTracker(file_rig, TrackerConfig(stills=True))
        (_, spots), = tracker.process(0, red, (x, y))[0]
        return tracker, next(s for s in spots if s.laser_id == rig.diodes[0].laser_id)

    _, exact = spot_zero(rig)
    assert exact.flags & LOST and exact.flags & OFF_PATH
    weak = replace(rig, diodes=(replace(rig.diodes[0], direction_sigma_deg=0.3),
                                *rig.diodes[1:]))
    tracker, found = spot_zero(weak)
    assert not found.flags & LOST
    assert np.hypot(found.x_px - truth_px[0], found.y_px - truth_px[1]) < 0.3
    gates = tracker.spots.tolerance_px
    assert gates[rig.diodes[0].laser_id] > 8.0
    assert all(gates[d.laser_id] == 4.0 for d in rig.diodes[1:])


def blobs_image(blobs: list[tuple[float, float, float]], seed: int, size: int = 200
                ) -> np.ndarray:
    """Gaussian blobs (x, y, amplitude over the background) on a dark background, with shot
    and read noise: a spot, or a glint far dimmer than one."""
    rows, columns = np.indices((size, size))
    light = np.full((size, size), 15.0)
    for x, y, amplitude in blobs:
        light += amplitude * np.exp(-0.5 * ((columns - x) ** 2 + (rows - y) ** 2) / 2.5**2)
    noise = np.random.default_rng(seed).normal(0.0, 1.0, light.shape) * np.sqrt(light + 4.0)
    return np.clip(np.round(light + noise), 0, 255).astype(np.uint8)


def spots_image(centres: list[tuple[float, float]], seed: int, size: int = 200) -> np.ndarray:
    """Saturating Gaussian spots (x, y) on a dark background, with shot and read noise."""
    return blobs_image([(x, y, 400.0) for x, y in centres], seed, size)


def straight_path(start: tuple[float, float], end: tuple[float, float]) -> np.ndarray:
    """A straight image path (15 points) from start to end (x, y) [px]."""
    return np.linspace(start, end, 15)


@pytest.mark.parametrize("seed", [1, 2])
def test_a_blob_near_two_paths_goes_to_the_diode_whose_spot_it_is(seed: int) -> None:
    """Diode 1's path runs 3 px from diode 0's spot, and diode 1's own spot is farther along
    its path (brighter blobs win a diode's own search: both take diode 0's, which is the
    brighter): each gets its own spot, in a still and in a video."""
    paths = {0: straight_path((100.0, 40.0), (100.0, 160.0)),
             1: straight_path((60.0, 97.0), (160.0, 97.0))}
    image = spots_image([(100.0, 100.0), (140.0, 97.0)], seed)
    image[95:106, 95:106] = np.maximum(image[95:106, 95:106], 250)   # diode 0's saturates
    for previous in (None, {0: (100.5, 99.0), 1: (138.0, 98.0)}):
        tracker = SpotTracker(paths)
        for laser_id, position in (previous or {}).items():
            tracker.previous[laser_id] = np.array(position)
        spots = {e.laser_id: e for e in tracker.update(image)}
        assert not spots[0].flags & LOST and not spots[1].flags & LOST
        assert np.hypot(spots[0].x_px - 100.0, spots[0].y_px - 100.0) < 0.3
        assert np.hypot(spots[1].x_px - 140.0, spots[1].y_px - 97.0) < 0.3


@pytest.mark.parametrize("seed", [1, 2])
def test_a_blob_two_diodes_claim_alike_is_neither_diodes(seed: int) -> None:
    """Two paths cross at a blob and one diode's spot is gone (off the liquid, foam): the
    blob cannot be told to be either's, so both are lost and flagged AMBIGUOUS; with the
    paths 6 px apart at the blob it is the nearer path's, and the other diode is lost."""
    from sds_tracker.spots import AMBIGUOUS

    image = spots_image([(100.0, 100.0)], seed)
    crossing = {0: straight_path((100.0, 40.0), (100.0, 160.0)),
                1: straight_path((40.0, 40.0), (160.0, 160.0))}
    spots = SpotTracker(crossing).update(image)
    assert all(e.flags & LOST and e.flags & AMBIGUOUS for e in spots)
    apart = {0: straight_path((100.0, 40.0), (100.0, 160.0)),
             1: straight_path((94.0, 40.0), (94.0, 160.0))}
    tracker = SpotTracker(apart, SpotSettings(path_tolerance_px=8.0))
    spots = {e.laser_id: e for e in tracker.update(image)}
    assert not spots[0].flags & LOST and np.hypot(spots[0].x_px - 100, spots[0].y_px - 100) < 0.3
    assert spots[1].flags & LOST and not spots[1].flags & AMBIGUOUS


def track_a_rendered_rig_as_built(repo: Path, seed: int, overrides: dict, frames: int
                                  ) -> tuple[list[int], dict[int, FrameTruth], list]:
    """The ground kick (half scale, `overrides` on top) of the rig as built for `seed`,
    rendered and tracked with the true rig: its diodes' ids in the truth's row order, each
    frame's truth and the tracker's output."""
    _, true = rig_as_built(load_rig(repo / "config" / "rigs" / "stelium.yaml"), AsBuilt(),
                           np.random.default_rng(seed))
    scenario = load_scenario(repo / "config" / "scenarios" / "ground_kick.yaml",
                             {"scale": 0.5, "seed": seed, **overrides})
    renderer = FrameRenderer(replace(scenario, rig=true))
    tracker = FrameTracker(replace(true, camera=true.camera.scaled(0.5)))
    truths, outputs = {}, []
    for index in range(frames):
        image, truths[index] = renderer.render(index)
        outputs += tracker.process(index, image[..., 2], (0, 0))[0]
    return [d.laser_id for d in true.diodes], truths, outputs + tracker.flush()


def errors_px(spots: list[TrackedSpot], truth: FrameTruth, ids: list[int]
              ) -> list[tuple[TrackedSpot, float, bool]]:
    """Each measured spot (not lost) with its raw position's distance [px] from its diode's
    truth, and whether the truth has that spot visible."""
    found = []
    for spot in spots:
        if is_lost(spot):
            continue
        k = ids.index(spot.laser_id)
        error = np.array([spot.x_raw_px, spot.y_raw_px]) - truth.spot_exposure_px[k]
        found.append((spot, float(np.hypot(*error)), bool(truth.visible[k])))
    return found


def test_two_diodes_whose_own_searches_take_each_others_spots_are_not_swapped(repo: Path
                                                                              ) -> None:
    """The real-images bench's held-out rig 59126 (clean images, half scale): the paths of
    diodes 4 and 15 pass within 1 and 2.2 px of each other's spots, so either assignment of
    the two blobs is nearly as good. Each diode's own search takes its brightest blob; in
    frame 24 they took each other's, no blob was shared, and both were swapped and valid
    (21 px off) to the end, the prior holding them there. Two diodes whose spots each lie in
    the other's path gate are now assigned jointly: ambiguous, both lost, in every frame."""
    ids, truths, outputs = track_a_rendered_rig_as_built(repo, 59126, {"duration_s": 1.0}, 30)
    assert len(outputs) == 30
    for index, spots in outputs:
        for spot, error_px, _ in errors_px(spots, truths[index], ids):
            assert error_px < 2.0, (index, spot)


def test_a_rig_as_built_whose_diode_took_anothers_spot_now_finds_its_own(repo: Path) -> None:
    """Rig as built 104 (development seed): diode 19's path passes diode 16's spot, which is
    brighter than its own on 8 of 16 static surfaces (the protocol's tilts about Y and the
    diagonal), and it took it, 40-50 px from its own, flagged only `reflection suspected`.
    Now every visible spot of the 4 surfaces where that happened most is its own diode's."""
    from sds_recon.calibration.lasers import KnownSurface
    from sds_sim.tilt_series import render_surfaces

    rng = np.random.default_rng(104)
    _, true = rig_as_built(load_rig(repo / "config" / "rigs" / "stelium.yaml"), AsBuilt(), rng)
    surfaces = [KnownSurface(0.0, 0.0, np.radians(a)) for a in (0.0, 5.0, 15.0, 20.0)]
    series = render_surfaces(true, surfaces, scale=0.5, seed=104)
    scaled = replace(true, camera=true.camera.scaled(0.5))
    x, y, w, h = scaled.container_region_px(scaled.camera, 30)
    ids = [d.laser_id for d in true.diodes]
    checked = 0
    for image, truth in zip(series.images, series.truths, strict=True):
        tracker = FrameTracker(scaled, TrackerConfig(stills=True))
        (_, spots), = tracker.process(0, image[y:y + h, x:x + w, 2], (x, y))[0]
        for spot in spots:
            k = ids.index(spot.laser_id)
            if truth.visible[k] and not is_lost(spot):
                checked += 1
                assert np.hypot(*(np.array([spot.x_px, spot.y_px]) -
                                  truth.spot_exposure_px[k])) < 1.0, spot
    assert checked >= 70


def test_a_blob_beside_the_lines_end_is_not_taken_for_line() -> None:
    """A wall reflection 19 px beside the line, 4 rows beyond its end and 12 rows long (as
    on a 35° still): the running median follows it there, so it was given as the line's
    first 12 rows; a run that short, cut off from the line by a step, is not the line."""
    from sds_tracker.line import LineSettings, seek_line

    rows, columns = np.indices((400, 300)).astype(float)
    line_x = 150.0 + 0.3 * (rows[:, 0] - 100)
    light = np.full(rows.shape, 15.0)
    on_line = (rows[:, 0] >= 100) & (rows[:, 0] <= 380)
    light[on_line] += 200.0 * np.exp(-0.5 * ((columns[on_line] - line_x[on_line, None]) / 1.5)
                                     ** 2)
    light += 220.0 * np.exp(-0.5 * (((columns - 131.0) / 2.5) ** 2 +
                                    ((rows - 90.5) / 3.0) ** 2))
    noise = np.random.default_rng(3).normal(0.0, 2.0, light.shape)
    image = np.clip(np.round(light + noise), 0, 255).astype(np.uint8)
    search = np.arange(60, 390)
    profile = seek_line(image, (0, 0), search, np.full(len(search), 110.0),
                        np.full(len(search), 240.0), LineSettings())
    assert profile.y_px.min() >= 100 and len(profile.y_px) > 250
    expected = 150.0 + 0.3 * (profile.y_px - 100)
    assert np.max(np.abs(profile.x_px - expected)) < 0.5


def test_beyond_the_level_lines_rows_the_line_is_taken_only_as_its_continuation() -> None:
    """The line (slope 0.3) runs on to row 60, past the level surface's rows (100-380); a
    saturated spot 3 px beside where it would run lies 12-35 rows past its end (rows 25-48),
    joined to it without a gap. Searched on every row, the line is its own to its end, and
    the spot's rows are not the line's."""
    from sds_tracker.line import LineSettings, continued_within, track_line

    rows, columns = np.indices((400, 300)).astype(float)
    line_x = 150.0 + 0.3 * (rows[:, 0] - 100)
    light = np.full(rows.shape, 15.0)
    on_line = (rows[:, 0] >= 60) & (rows[:, 0] <= 380)
    light[on_line] += 200.0 * np.exp(-0.5 * ((columns[on_line] - line_x[on_line, None]) / 1.5)
                                     ** 2)
    spot_x = 150.0 + 0.3 * (36.5 - 100) + 3.0
    light += 600.0 * np.exp(-0.5 * (((columns - spot_x) / 5.0) ** 2 +
                                    ((rows - 36.5) / 5.0) ** 2))
    noise = np.random.default_rng(5).normal(0.0, 2.0, light.shape)
    image = np.clip(np.round(light + noise), 0, 255).astype(np.uint8)
    search = np.arange(10, 395)
    settings = LineSettings()
    measured = track_line(image, (0, 0), 150.0 + 0.3 * (search - 100.0), search, settings)
    assert measured.y_px.min() < 50   # the spot's rows, joined to the line's
    line = continued_within(measured, 100, 380, settings)
    assert 58 <= line.y_px.min() <= 62 and line.y_px.max() >= 378
    expected = 150.0 + 0.3 * (line.y_px - 100)
    assert np.max(np.abs(line.x_px - expected)) < 0.5


@pytest.mark.parametrize("spot_at_end", [False, True])
def test_a_lines_end_is_its_own_unless_light_lies_past_it(spot_at_end: bool) -> None:
    """A line that ends at row 200: past its end the rows are dark, so it ends there. With a
    saturated spot 6 px beside its end, the line's samples on the spot's rows (left out, as
    rows that stray from their neighbours are) end 15 rows before it: the spot's light past
    that end may hide more of the line, and the end is not taken as the line's own
    (`end_is_dark`). Its first row, bare, is."""
    from sds_tracker.line import LineProfile, LineSettings, end_is_dark, track_line

    rows, columns = np.indices((300, 300)).astype(float)
    line_x = 150.0 + 0.3 * (rows[:, 0] - 100)
    light = np.full(rows.shape, 15.0)
    on_line = (rows[:, 0] >= 60) & (rows[:, 0] <= 200)
    light[on_line] += 200.0 * np.exp(-0.5 * ((columns[on_line] - line_x[on_line, None]) / 1.5)
                                     ** 2)
    light += 900.0 * spot_at_end * np.exp(-0.5 * (((columns - line_x[200] - 6.0) / 5.0) ** 2
                                                  + ((rows - 200.0) / 5.0) ** 2))
    noise = np.random.default_rng(4).normal(0.0, 2.0, light.shape)
    image = np.clip(np.round(light + noise), 0, 255).astype(np.uint8)
    settings = LineSettings()
    search = np.arange(20, 280)
    measured = track_line(image, (0, 0), 150.0 + 0.3 * (search - 100.0), search, settings)
    assert measured.y_px.min() == 60
    if spot_at_end:
        kept = measured.y_px < 185
        measured = LineProfile(measured.x_px[kept], measured.y_px[kept],
                               measured.sigma_px[kept], measured.peak[kept],
                               measured.flags[kept])
    else:
        assert measured.y_px.max() == 200
    assert end_is_dark(image, (0, 0), measured, -1, settings)
    assert end_is_dark(image, (0, 0), measured, 1, settings) != spot_at_end


def rim_and_spot(spot: tuple[float, float] | None, seed: int) -> np.ndarray:
    """The demo's failure: the container's rim lit by ambient light (a 4 px grey stripe 35
    grey levels above the dark liquid, as the simulator renders it) across a diode's path,
    60 px from where its spot is, the spot there or dropped out."""
    image = spots_image([] if spot is None else [spot], seed).astype(float)
    rows, columns = np.indices(image.shape)
    across = (columns - 40.0) - 0.5 * (rows - 100.0)   # the rim crosses the path at x = 40
    image += 35.0 * (np.abs(across) <= 2.0)
    return np.clip(image, 0, 255).astype(np.uint8)


@pytest.mark.parametrize("seed", [1, 2])
def test_the_containers_rim_across_a_path_is_no_spot(seed: int) -> None:
    """A spot that drops out for a frame (foam, a glint) is lost, in a first search along
    its whole path and where it was tracked, not replaced by the rim where the rim crosses
    its path (a point 60 px off, marked valid); when it comes back it is its own again, and
    a spot the rim is beside is found where it is."""
    path = straight_path((20.0, 100.0), (180.0, 100.0))
    for previous in (None, (100.0, 100.0), (44.0, 100.0)):
        tracker = SpotTracker({0: path})
        tracker.previous[0] = None if previous is None else np.array(previous)
        (gone,) = tracker.update(rim_and_spot(None, seed))
        assert gone.flags & LOST and np.isnan(gone.x_px), (previous, gone)
        (back,) = tracker.update(rim_and_spot((100.0, 100.0), seed))
        assert np.hypot(back.x_px - 100.0, back.y_px - 100.0) < 0.3, (previous, back)
    (beside,) = SpotTracker({0: path}).update(rim_and_spot((56.0, 100.0), seed))
    assert np.hypot(beside.x_px - 56.0, beside.y_px - 100.0) < 0.5, beside


@pytest.mark.parametrize("seed", [1, 2])
def test_a_glint_on_the_path_of_a_spot_gone_for_two_frames_is_not_it(seed: int) -> None:
    """The held-out demo run's fabricated point (seed 55110): a spot hidden for two frames,
    and in the second a glint on its path 36 px from where it was last seen. The glint was
    taken (a valid point 12.6 mm off, and the next frame's spot pulled 3 px towards it);
    it is out of reach (`REACQUIRE_FRAMES`): lost both frames, and the spot is its own when
    it comes back. Gone longer, the spot is looked for along its whole path again."""
    path = straight_path((20.0, 100.0), (180.0, 100.0))
    tracker = SpotTracker({0: path})
    (seen,) = tracker.update(spots_image([(100.0, 100.0)], seed))
    assert np.hypot(seen.x_px - 100.0, seen.y_px - 100.0) < 0.3
    for frame, others in enumerate(([], [(136.0, 100.0)])):
        (gone,) = tracker.update(spots_image(others, seed + frame))
        assert gone.flags & LOST and np.isnan(gone.x_px), (frame, gone)
    (back,) = tracker.update(spots_image([(101.0, 100.0)], seed))
    assert np.hypot(back.x_px - 101.0, back.y_px - 100.0) < 0.3, back
    for frame in range(REACQUIRE_FRAMES + 1):
        (gone,) = tracker.update(spots_image([], seed + frame))
        assert gone.flags & LOST
    (far,) = tracker.update(spots_image([(160.0, 100.0)], seed))
    assert np.hypot(far.x_px - 160.0, far.y_px - 100.0) < 0.3, far


@pytest.mark.parametrize("seed", [1, 2])
def test_a_dim_glint_beside_a_spot_that_dropped_out_is_not_it(seed: int) -> None:
    """The fresh held-out demo run's fabricated points (seeds 56101-56120): in the first frame
    a spot is hidden, a glint 5 px away with a fifth of its peak lies in the spot's own window
    and was taken for it, so the spot never counted as lost. A blob below DIMMED_SHARE of the
    spot's peak when last seen is not it; an unsaturated spot whose peak halves under speckle
    (true spots on development rigs fell to 0.43 at the least) is still itself."""
    path = straight_path((20.0, 100.0), (180.0, 100.0))
    tracker = SpotTracker({0: path})
    (seen,) = tracker.update(spots_image([(100.0, 100.0)], seed))
    assert np.hypot(seen.x_px - 100.0, seen.y_px - 100.0) < 0.3 and seen.peak == 255
    (gone,) = tracker.update(blobs_image([(105.0, 100.0, 40.0)], seed + 1))
    assert gone.flags & LOST and np.isnan(gone.x_px), gone
    (back,) = tracker.update(spots_image([(100.5, 100.0)], seed + 2))
    assert np.hypot(back.x_px - 100.5, back.y_px - 100.0) < 0.3, back
    tracker = SpotTracker({0: path})
    for frame, amplitude in enumerate((150.0, 75.0, 150.0)):
        (spot,) = tracker.update(blobs_image([(100.0 + frame, 100.0, amplitude)], seed + frame))
        assert not spot.flags & LOST and abs(spot.x_px - 100.0 - frame) < 0.3, (frame, spot)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_small_bright_glint_where_a_saturated_spot_dropped_out_is_not_it(seed: int) -> None:
    """The held-out run's fabricated point (rig 65106): a saturated spot dropped out, and a
    one-frame glint lit 1.5 px from it, 2x2 px above 75 grey levels: its peak was 0.45 of the
    spot's, above DIMMED_SHARE, and it was measured as the spot (valid, σ 0.24 px). Its light
    is a few hundredths of the spot's (SMALLER_LIGHT_SHARE): lost; the spot back is its own."""
    path = straight_path((20.0, 100.0), (180.0, 100.0))
    tracker = SpotTracker({0: path})
    (seen,) = tracker.update(spots_image([(100.0, 100.0)], seed))
    assert np.hypot(seen.x_px - 100.0, seen.y_px - 100.0) < 0.3 and seen.peak == 255
    rows, columns = np.indices((200, 200))
    glint = 100.0 * np.exp(-0.5 * ((columns - 101.5) ** 2 + (rows - 100.0) ** 2) / 0.9**2)
    image = np.clip(blobs_image([], seed + 1) + np.round(glint), 0, 255).astype(np.uint8)
    assert image.max() >= 0.3 * 255   # as bright as the peak check lets through
    (gone,) = tracker.update(image)
    assert gone.flags & LOST and np.isnan(gone.x_px), gone
    (back,) = tracker.update(spots_image([(100.5, 100.0)], seed + 2))
    assert np.hypot(back.x_px - 100.5, back.y_px - 100.0) < 0.3, back


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_grain_of_a_blooming_spots_halo_on_a_path_is_no_spot(seed: int) -> None:
    """The held-out still's wrong spot (rig 71019): speckle broke a blooming spot's halo into
    islands, and one, a pixel of 0.03 % of the blob's light, lay on a diode's path while the
    blob's centroid lay just beyond the path's tolerance; the search took the grain (valid,
    11 px off). Here a saturated spot with a wide halo lies 6 px from a path, and a grain of
    its halo, cut off by a ring of dark speckle, lies on the path: the diode is lost, not the
    grain. The diode whose path runs through the spot measures it."""
    rows, columns = np.indices((200, 200))
    halo = 60.0 * np.exp(-0.5 * ((columns - 100.0) ** 2 + (rows - 100.0) ** 2) / 8.0**2)
    image = blobs_image([(100.0, 100.0, 400.0)], seed) + halo
    image[103:106, 105:108] = 15.0   # a dark ring of speckle around the grain
    image[104, 106] = 60.0
    image = np.clip(np.round(image), 0, 255).astype(np.uint8)
    (beside,) = SpotTracker({0: straight_path((106.0, 20.0), (106.0, 180.0))}).update(image)
    assert beside.flags & LOST and np.isnan(beside.x_px), beside
    (through,) = SpotTracker({0: straight_path((100.0, 20.0), (100.0, 180.0))}).update(image)
    assert np.hypot(through.x_px - 100.0, through.y_px - 100.0) < 0.3, through


@pytest.mark.parametrize("seed", [1, 2])
def test_a_dim_blob_on_the_path_of_a_spot_hidden_in_the_first_frame_is_not_it(seed: int
                                                                            ) -> None:
    """The held-out demo run's wrong point (seed 61305): in the video's first frame a spot
    was hidden, and the container's rim on its path, lit by ambient light (0.22-0.30 of the
    other spots' peaks), was taken for it, 67 px off and valid; nothing had seen the spot
    before to vouch for it or against it. A blob below FAINT_SHARE of the frame's other
    spots is no spot there; an unsaturated spot at 0.84 of them (true spots clear of the
    laser line on development rigs: 0.81 at the least) is one, and a spot tracked from the
    frame before is judged against its own peak alone (DIMMED_SHARE): at 0.44 of it (0.37 of
    the others) it is still itself."""
    rows = (30.0, 60.0, 90.0, 120.0, 150.0)
    paths = {k: straight_path((20.0, y), (180.0, y)) for k, y in enumerate(rows)}
    saturated = [(100.0, y, 400.0) for y in rows[:4]]
    tracker = SpotTracker(paths)
    spots = tracker.update(blobs_image([*saturated, (70.0, rows[4], 60.0)], seed))
    assert all(not spot.flags & LOST for spot in spots[:4]), spots
    assert spots[4].flags & LOST and np.isnan(spots[4].x_px), spots[4]
    tracker = SpotTracker(paths)
    spots = tracker.update(blobs_image([*saturated, (70.0, rows[4], 200.0)], seed))
    assert not spots[4].flags & LOST and abs(spots[4].x_px - 70.0) < 0.3, spots[4]
    spots = tracker.update(blobs_image([*saturated, (71.0, rows[4], 80.0)], seed + 1))
    assert not spots[4].flags & LOST and abs(spots[4].x_px - 71.0) < 0.3, spots[4]


def brightening_line_frame(seed: int, spot: tuple[float, float] | None, brightening: float,
                           size: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """A frame with a speckled laser line (20 % from pixel to pixel) that brightens by
    `brightening` over some 16 rows about row 100 (the liquid focusing it), and optionally a
    saturating spot; and the line's columns."""
    line_x = 100.3 + 0.02 * (np.arange(size) - 100)
    gain = 1 + (brightening - 1) * np.exp(-0.5 * ((np.arange(size) - 100) / 8.0) ** 2)
    return line_frame(seed, spot, line_x, 150.0 * gain, 0.2, size), line_x


@pytest.mark.parametrize("seed", range(4))
def test_a_spot_gone_beside_a_brightening_line_is_not_the_lines_light(seed: int) -> None:
    """The codec case's fabricated point (development seed 7002, diode 18): a spot hidden for
    five frames, its path crossing a laser line that changed along its length; what the
    line's median profile left of it was taken for the spot, 26 px off and valid. Here the
    line doubles its brightness over the rows the path crosses, the spot's hidden for three
    frames: before DIMMED_SHARE was judged on a line-overlapping spot's own light beside the
    line, the line's light was taken for it in 1-2 of the 3 frames in each of these seeds. The
    spot is lost while hidden, and found where it comes back on the line."""
    path = np.array([[40.0, 100.0], [160.0, 100.0]])
    tracker = SpotTracker({0: path}, SpotSettings())
    image, line_x = brightening_line_frame(seed, (86.0, 100.0), 1.0)
    line = (np.arange(200.0), line_x)
    (seen,) = tracker.update(image, (0, 0), line)
    assert np.hypot(seen.x_px - 86.0, seen.y_px - 100.0) < 0.3, seen
    for frame in range(3):
        image, _ = brightening_line_frame(10 * seed + frame + 1, None, 2.0)
        (gone,) = tracker.update(image, (0, 0), line)
        assert gone.flags & LOST and np.isnan(gone.x_px), (frame, gone)
    image, _ = brightening_line_frame(10 * seed + 9, (98.0, 100.4), 2.0)
    (back,) = tracker.update(image, (0, 0), line)
    assert np.hypot(back.x_px - 98.0, back.y_px - 100.4) < 0.5, back


def speckled_line_and_spot(rng: np.random.Generator, spot: np.ndarray | None, line_x: float,
                           size: int = 160) -> np.ndarray:
    """A frame with a laser line saturating 2.4 times over (σ 1.8 px, column `line_x`) and
    optionally a spot (σ 2.5 px, peak 400), both under laser speckle of contrast 0.74 and a
    grain of 0.75 px (the real-images bench's held-out rig 60108), photon and read noise."""
    rows, columns = np.mgrid[0:size, 0:size].astype(float)
    light = 600.0 * np.exp(-0.5 * ((columns - line_x) / 1.8) ** 2)
    if spot is not None:
        light += 400.0 * np.exp(-0.5 * ((columns - spot[0]) ** 2 + (rows - spot[1]) ** 2)
                                / 2.5**2)
    light = 10.0 + speckle_pattern(rng, (size, size), 0.74, 0.75) * light
    noisy = light + rng.normal(size=light.shape) * np.sqrt(light + 4.0)
    return np.clip(np.round(noisy), 0, 255).astype(np.uint8)


def test_a_centre_still_moving_after_its_rounds_is_not_known(monkeypatch: pytest.MonkeyPatch
                                                             ) -> None:
    """A spot's measurement without the line's light is made again from where it lands until
    it settles (`settled_line_free_centre`). On the development stills (rig 7113) the third
    of three measurements, each 10-18 px from the last, was given as a saturated spot on the
    line: 2.1 px off with σ 0.13 px. A centre that moved more than a pixel in the last round
    is not known; one that lands where it was started is given, and so is one of two centres
    0.6 px apart that the rounds alternate between (a speckled spot beside the line)."""
    image = np.zeros((100, 100), np.uint8)
    line = (np.arange(100.0), np.full(100, 50.0))
    along = np.array([0.0, 1.0])

    def moving_on(image: np.ndarray, origin: np.ndarray, centre: np.ndarray,
                  line: tuple[np.ndarray, np.ndarray], s: SpotSettings) -> LineFreeSpot:
        return LineFreeSpot(centre + np.array([10.0, 0.0]), along, -1.0)

    def landing_at_60(image: np.ndarray, origin: np.ndarray, centre: np.ndarray,
                      line: tuple[np.ndarray, np.ndarray], s: SpotSettings) -> LineFreeSpot:
        return LineFreeSpot(np.array([60.0, 50.0]), along, -1.0)

    monkeypatch.setattr(spots_module, "line_free_centre", moving_on)
    moving = settled_line_free_centre(image, np.zeros(2), np.array([20.0, 50.0]), line,
                                      SpotSettings())
    assert moving is not None and np.isnan(moving.centre).all()
    monkeypatch.setattr(spots_module, "line_free_centre", landing_at_60)
    settled = settled_line_free_centre(image, np.zeros(2), np.array([20.0, 50.0]), line,
                                       SpotSettings())
    assert settled is not None and np.allclose(settled.centre, [60.0, 50.0])

    def alternating(image: np.ndarray, origin: np.ndarray, centre: np.ndarray,
                    line: tuple[np.ndarray, np.ndarray], s: SpotSettings) -> LineFreeSpot:
        return LineFreeSpot(np.array([60.6 if centre[0] == 60.0 else 60.0, 50.0]), along, -1.0)

    monkeypatch.setattr(spots_module, "line_free_centre", alternating)
    jittering = settled_line_free_centre(image, np.zeros(2), np.array([20.0, 50.0]), line,
                                         SpotSettings())
    assert jittering is not None and np.isfinite(jittering.centre).all()


def test_the_speckled_lines_light_beside_a_hidden_spot_is_not_it() -> None:
    """The real-images bench's held-out rig 60108 (speckle): a spot tracked 4 px beside a
    saturated laser line, hidden for three frames; in the first, what the line's profile
    left of its speckled wing 3 px away was taken for it (valid). Its brightest pixel was
    the line's, so the dimming test (DIMMED_SHARE) passed it. Now a spot measured with the
    line's light taken away is told by its own light, and light beside the line is a spot's
    only where it rises LINE_SPECKLE_PEAK times above what the line's speckle leaves at that
    offset from the line. Here, 30 such spots in a video's fixed aperture, each seen once and
    hidden for three frames: before, 24 of the 90 hidden frames gave a spot (7 with the first
    change alone); now none. While it is there, 27 of the 30 are found, 0.85-2.5 px off; seed
    7's measurement without the line's light alternates between two centres, 1.2 px off and
    3.3 px off on the line, and so is not known (`settled_line_free_centre`), and seeds 12's
    and 24's centres of symmetry have a flat side (HIDDEN_CENTRE_RISE; found before it)."""
    size, line_x = 160, 80.3
    line = (np.arange(float(size)), np.full(size, line_x))
    fabricated, found = [], 0
    for seed in range(30):
        rng = np.random.default_rng(seed)
        spot = np.array([line_x + 4.0, 81.0]) + rng.uniform(-0.5, 0.5, 2)
        tracker = SpotTracker({0: spot + np.array([[0.0, -40.0], [0.0, 40.0]])},
                              apertures_px={0: 6.0})
        (seen,) = tracker.update(speckled_line_and_spot(rng, spot, line_x), (0, 0), line)
        # Found in the spot's own light (within 2 σ of its profile): acquired this close to
        # a line this bright and speckled, it is 0.85-3.9 px off (as before this change).
        if not seen.flags & LOST:
            assert np.hypot(seen.x_px - spot[0], seen.y_px - spot[1]) < 5.0, (seed, seen)
            found += 1
        for frame in range(3):
            (gone,) = tracker.update(speckled_line_and_spot(rng, None, line_x), (0, 0), line)
            if not gone.flags & LOST:
                fabricated.append((seed, frame, gone))
    assert not fabricated, fabricated
    assert found >= 27


def bent_line_frame(seed: int, spot: tuple[float, float] | None, bend_px: float,
                    size: int = 200) -> np.ndarray:
    """A frame with a laser line (speckle 10 %) that bends `bend_px` sideways over some 10
    rows about row 100 (a ripple on the liquid), and optionally a saturating spot."""
    line_x = 100.3 + bend_px * np.exp(-0.5 * ((np.arange(size) - 100) / 4.0) ** 2)
    return line_frame(seed, spot, line_x, 230.0, 0.1, size)


@pytest.mark.parametrize("bend_px", [1.0, 3.0])
def test_a_bend_of_the_line_along_a_path_is_no_spot(bend_px: float) -> None:
    """The real-images bench's held-out rig 59140 (motion blur): a spot on the laser line,
    its path along the line, hidden for six frames, was then looked for along its whole path,
    and a bend of the line 40 px away was acquired as the spot (valid, 25-37 px off). What
    the line's straight profile leaves of a bend is a crest beside a trough; a spot only adds
    light (`line_bends`). A bend of 1 or 3 px is no spot (before: taken, 1.3-2.6 px beside
    the line); a spot on the bend is acquired."""
    path = np.array([[101.5, 20.0], [101.5, 180.0]])
    line = (np.arange(200.0), np.full(200, 100.3))
    for seed in range(3):
        (bend,) = SpotTracker({0: path}).update(bent_line_frame(seed, None, bend_px), (0, 0),
                                                line)
        assert bend.flags & LOST and np.isnan(bend.x_px), (seed, bend)
        (spot,) = SpotTracker({0: path}).update(
            bent_line_frame(seed, (101.0, 100.0), bend_px), (0, 0), line)
        assert np.hypot(spot.x_px - 101.0, spot.y_px - 100.0) < 0.5, (seed, spot)


def speckle_pattern(rng: np.random.Generator, shape: tuple[int, int], contrast: float,
                    grain_px: float) -> np.ndarray:
    """A laser speckle pattern of mean 1: a fully developed pattern (the squared modulus of a
    complex Gaussian field smoothed to a grain of `grain_px`) mixed down to `contrast`."""
    field = gaussian_filter(rng.normal(size=shape), grain_px) + \
        1j * gaussian_filter(rng.normal(size=shape), grain_px)
    intensity = np.abs(field) ** 2
    return (1 - contrast) + contrast * intensity / intensity.mean()


@pytest.mark.parametrize("beside_px", [2.0, 4.0])
def test_an_unsaturated_spot_on_a_speckled_line_says_it_is_uncertain(beside_px: float
                                                                      ) -> None:
    """A dim spot (peak 180) overlapping a saturating line, both under speckle (contrast 0.5):
    what the line's profile leaves of its speckle moves the spot's centre by a pixel or two,
    and its σ says so (`line_speckle_sigma_px`, `symmetry_spreads`) instead of the saturated
    spots' 0.13 px, or the spot is not measured: where its centre of symmetry has a flat side
    (HIDDEN_CENTRE_RISE). Measured over 40 frames, 2 and 4 px beside the line: 34 and 40
    measured, error/σ RMS 1.80 and 1.52 (the rest is a push away from the line, which no σ
    holds; with the line's speckle alone in the σ, 40 measured: 3.9 and 3.3, and before it
    11.8 and 7.4); bound at 2.5, and at 30 measured."""
    ratios, sigmas = [], []
    size = 160
    rows, columns = np.mgrid[0:size, 0:size].astype(float)
    line_x = np.full(size, 80.3)
    for seed in range(40):
        rng = np.random.default_rng(seed)
        spot = np.array([80.3 - beside_px, 81.0]) + rng.uniform(-0.5, 0.5, 2)
        light = 10.0 + speckle_pattern(rng, (size, size), 0.5, 1.0) * (
            300.0 * np.exp(-0.5 * ((columns - line_x[:, None]) / 1.8) ** 2) +
            180.0 * np.exp(-0.5 * ((columns - spot[0]) ** 2 + (rows - spot[1]) ** 2) / 3.0**2))
        noisy = light + rng.normal(size=light.shape) * np.sqrt(light + 4.0)
        image = np.clip(np.round(noisy), 0, 255).astype(np.uint8)
        tracker = SpotTracker({0: spot + np.array([[0.0, -40.0], [0.0, 40.0]])}, SpotSettings())
        tracker.previous[0] = spot + np.array([0.5, 0.5])
        (estimate,) = tracker.update(image, (0, 0), (np.arange(size), line_x))
        if estimate.flags & LOST:
            continue
        error = np.hypot(estimate.x_px - spot[0], estimate.y_px - spot[1])
        ratios.append(error / np.sqrt(2) / estimate.sigma_px)
        sigmas.append(estimate.sigma_px)
    assert len(ratios) >= 30
    assert np.median(sigmas) > 2 * ON_LINE_SIGMA_PX[1]
    assert np.sqrt(np.mean(np.square(ratios))) < 2.5


@pytest.mark.parametrize("seed", [1, 2])
def test_a_spot_that_vanishes_is_not_replaced_by_a_blob_beyond_a_frames_motion(seed: int
                                                                                ) -> None:
    """The fourth held-out demo run's wrong point (seed 57105): a spot tracked up to the video's
    last frame vanished there, and a blob 27 px away with a third of its peak, inside its
    window, was taken for it (a valid point 8.9 mm off). A spot measured k frames ago is
    looked for within (k + 1) × `prior_sigma_px` of where it was: the blob is beyond it, so
    the spot is lost. A spot moving 12 px per frame, half again the fastest in the shipped
    scenarios, is still followed."""
    path = straight_path((20.0, 20.0), (180.0, 180.0))
    tracker = SpotTracker({0: path})
    (seen,) = tracker.update(spots_image([(100.0, 100.0)], seed))
    assert np.hypot(seen.x_px - 100.0, seen.y_px - 100.0) < 0.3
    (gone,) = tracker.update(blobs_image([(119.0, 119.0, 100.0)], seed + 1))
    assert gone.flags & LOST and np.isnan(gone.x_px), gone
    tracker = SpotTracker({0: path})
    for frame in range(6):
        x = 40.0 + 12.0 / np.sqrt(2) * frame
        (spot,) = tracker.update(spots_image([(x, x)], seed + frame))
        assert np.hypot(spot.x_px - x, spot.y_px - x) < 0.3, (frame, spot)


def speckled_spots_error_over_sigma(contrast: float, peak: float, seed: int,
                                    fixed_aperture: bool = True, spot_px: float = 2.0,
                                    bloom: float = 0.0) -> float:
    """error/σ RMS of six spots (σ `spot_px`, `peak` over a background of 10, shot and read
    noise) under laser speckle of `contrast` (grain 1 px, new in each of 30 frames), with
    `bloom` of the light beyond 255 spread as a halo (a Gaussian of 6 px, as the simulator's
    bloom), tracked in fixed apertures of 6 px from 0.4 px off, or (not `fixed_aperture`)
    each frame as a still: each spot found on its path and measured by the clipped centroid
    of its blob."""
    size = 200
    rows, columns = np.mgrid[0:size, 0:size].astype(float)
    centres = np.array([[x, y] for y in (50.0, 150.0) for x in (40.0, 100.0, 160.0)])
    paths = {k: centre + np.array([[0.0, -40.0], [0.0, 40.0]])
             for k, centre in enumerate(centres)}
    tracker = SpotTracker(paths, SpotSettings(),
                          apertures_px=dict.fromkeys(paths, 6.0) if fixed_aperture else None)
    ratios = []
    for frame in range(30):
        rng = np.random.default_rng(seed + frame)
        spots = centres + rng.uniform(-0.5, 0.5, centres.shape)
        light = sum(peak * np.exp(-0.5 * ((columns - x) ** 2 + (rows - y) ** 2) / spot_px**2)
                    for x, y in spots)
        light = 10.0 + light * speckle_pattern(rng, (size, size), contrast, 1.0)
        light = light + bloom * gaussian_filter(np.maximum(light - 255.0, 0.0), 6.0)
        noisy = light + rng.normal(size=light.shape) * np.sqrt(light + 4.0)
        image = np.clip(np.round(noisy), 0, 255).astype(np.uint8)
        if fixed_aperture:
            for k, spot in enumerate(spots):
                tracker.previous[k] = spot + 0.3
        else:
            tracker.forget()
        for estimate in tracker.update(image, (0, 0)):
            if estimate.flags & LOST and not fixed_aperture:
                continue   # a still's spot may break up into grains: not judged here
            assert not estimate.flags & LOST
            error = np.array([estimate.x_px, estimate.y_px]) - spots[estimate.laser_id]
            ratios.append(np.sum(error**2) / 2 / estimate.sigma_px**2)
    return float(np.sqrt(np.mean(ratios)))


@pytest.mark.parametrize("peak", [150.0, 600.0])
def test_a_speckled_spots_sigma_holds_its_speckle(peak: float) -> None:
    """Under laser speckle (contrast 0.5) a spot's centre moves from frame to frame far more
    than its photons say: its σ takes in the speckle its own light shows (`_with_speckle`).
    Measured over four seeds: error/σ RMS 1.65-1.81 unsaturated and 1.68-1.80 saturating
    (the photons' σ alone: 5.2-5.4 and 7.3-7.4); bound at 2.5. Without speckle the σ stays
    the photons': 1.00-1.03 and 0.86-0.92 (alone 1.04-1.05 and 0.99-1.00); bound 0.75-1.2."""
    assert speckled_spots_error_over_sigma(0.5, peak, 0) < 2.5
    assert 0.75 < speckled_spots_error_over_sigma(0.0, peak, 1000) < 1.2


@pytest.mark.parametrize("peak", [150.0, 600.0])
def test_a_speckled_stills_sigma_holds_its_speckle(peak: float) -> None:
    """A still's spot (found on its path, measured by the clipped centroid of its blob) also
    takes in the speckle its own light shows: on the development stills (rigs 7101-7116)
    the σ was the photons' alone, error/σ RMS 2.27. Measured over four seeds: 1.32-1.47
    unsaturated and 1.27-1.42 saturating (the photons' σ alone: 4.2-4.6 and 4.9-5.2);
    bound at 2.0. Without speckle 0.59-0.64 and 0.50-0.59 (the clipped centroid's photon σ
    is on the safe side); bound 0.4-1.2."""
    assert speckled_spots_error_over_sigma(0.5, peak, 0, fixed_aperture=False) < 2.0
    assert 0.4 < speckled_spots_error_over_sigma(0.0, peak, 1000, fixed_aperture=False) < 1.2


def test_a_still_spot_far_past_saturation_holds_its_speckle() -> None:
    """A still's spot ten times brighter than saturation (σ 3 px, peak 1500) with a bloom
    halo (0.2 of its light beyond saturation, over 6 px): its speckle shows as its plateau's
    ragged edge, and its unsaturated wings are much of them its bloom, whose light shows no
    speckle. The larger of the two readings (`_with_speckle`,
    `kernels.clipped_speckle_sigmas_px`) holds it. Measured over four seeds (0, 100, 200,
    300): error/σ RMS 1.29-1.39 (the wings' contrast alone: 1.54-1.69); bound at 1.5.
    Without speckle 0.43-0.51 (the clipped centroid's photon σ, on the safe side); bound
    0.35-1.2."""
    far_past = {"fixed_aperture": False, "spot_px": 3.0, "bloom": 0.2}
    assert speckled_spots_error_over_sigma(0.5, 1500.0, 0, **far_past) < 1.5
    assert 0.35 < speckled_spots_error_over_sigma(0.0, 1500.0, 1000, **far_past) < 1.2


def surface_paths(count: int) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray],
                                       np.ndarray]:
    """`count` vertical beams on a circle of radius 30 mm, each one's image path a row of a
    300 px image (26 px apart) from x 30 px (height −40 mm) to 270 px (+40 mm): the paths,
    the beams' points at the paths' 15 heights [mm], and each beam's (x, y) [mm]."""
    angles = 2 * np.pi * np.arange(count) / count
    places = 30.0 * np.c_[np.cos(angles), np.sin(angles)]
    heights = np.linspace(-40.0, 40.0, 15)
    paths = {k: straight_path((30.0, 20.0 + 26 * k), (270.0, 20.0 + 26 * k))
             for k in range(count)}
    beams = {k: np.c_[np.repeat(places[k][None], 15, axis=0), heights] for k in range(count)}
    return paths, beams, places


@pytest.mark.parametrize("seed", [1, 2])
def test_a_still_takes_the_spot_on_the_surface_not_a_brighter_ghost_on_its_path(seed: int
                                                                               ) -> None:
    """The protocol's stills of development rigs (7101-7105): a wall's reflection on a
    diode's path, saturated and larger than its spot, was taken for it in 19 of 1024 spots
    (37-168 px off, valid, flagged only `reflection suspected`), and a glint on the path of
    a hidden spot once. Each stood for a point 14-58 mm off the surface the other spots
    show. Here ten beams see a tilted surface; diode 3's path also holds a larger, brighter
    blob where its beam would meet a surface 20 mm higher: its spot is taken, not that
    blob, and with its spot hidden it is lost, not that blob."""
    paths, beams, places = surface_paths(10)
    heights = 3.0 + 0.15 * places[:, 0] - 0.1 * places[:, 1]
    spots = [(30.0 + 3.0 * (height + 40.0), 20.0 + 26.0 * k, 400.0)
             for k, height in enumerate(heights)]
    ghost = (spots[3][0] + 60.0, spots[3][1], 1500.0)
    for hidden in (False, True):
        blobs = [*spots[:3], *([] if hidden else [spots[3]]), *spots[4:], ghost]
        tracker = SpotTracker(paths, beams_mm=beams)
        found = tracker.update(blobs_image(blobs, seed, size=300))
        for k, spot in enumerate(found):
            if k == 3 and hidden:
                assert spot.flags & LOST and np.isnan(spot.x_px), spot
            else:
                assert np.hypot(spot.x_px - spots[k][0], spot.y_px - spots[k][1]) < 0.3, \
                    (k, spot)


@pytest.mark.parametrize("seed", [1, 2])
def test_a_still_spot_joined_to_its_own_wall_reflection_is_lost_not_pulled(seed: int) -> None:
    """The protocol's stills of development rigs (7101-7116): a spot whose own wall
    reflection lay 5-20 px from it, their light joined above the threshold, was measured
    2-9 px towards it (10 of the 16 spots more than 2 px off). Here ten beams see a tilted
    surface; diode 3's reflection, half as bright as its spot, lies 10 px from it, their
    light joined; diode 6's 17 px from its spot, apart. The reflections are where the model
    given to the tracker puts them from the points where the beams meet the fitted surface:
    9 and 16 px along and 5 px across the paths from the images of those points (the
    paths give them: x = 30 + 3 (z + 40) px). Diode 3 is lost, flagged as a reflection;
    diode 6 and the others are measured. Without the model diode 3 is measured more than
    1 px towards its reflection."""
    paths, beams, places = surface_paths(10)
    heights = 3.0 + 0.15 * places[:, 0] - 0.1 * places[:, 1]
    spots = [(30.0 + 3.0 * (height + 40.0), 20.0 + 26.0 * k, 400.0)
             for k, height in enumerate(heights)]
    beside_px = {3: 9.0, 6: 16.0}
    reflections = [(spots[k][0] + offset, spots[k][1] + 5.0, 200.0)
                   for k, offset in beside_px.items()]
    image = blobs_image([*spots, *reflections], seed, size=300)

    def reflections_px(laser_ids: list[int], points_mm: np.ndarray,
                       normals: np.ndarray) -> np.ndarray:
        assert np.all(normals[:, 2] > 0.9)
        pixels = np.full((len(laser_ids), 2), np.nan)
        for row, (laser_id, point) in enumerate(zip(laser_ids, points_mm, strict=True)):
            if laser_id in beside_px:
                pixels[row] = (30.0 + 3.0 * (point[2] + 40.0) + beside_px[laser_id],
                               20.0 + 26.0 * laser_id + 5.0)
        return pixels

    found = SpotTracker(paths, beams_mm=beams, reflections_px=reflections_px).update(image)
    for k, spot in enumerate(found):
        if k == 3:
            assert spot.flags & LOST and spot.flags & REFLECTION_SUSPECTED, spot
            assert np.isnan(spot.x_px)
        else:
            assert np.hypot(spot.x_px - spots[k][0], spot.y_px - spots[k][1]) < 0.3, (k, spot)
    pulled = SpotTracker(paths, beams_mm=beams).update(image)[3]
    assert np.hypot(pulled.x_px - spots[3][0], pulled.y_px - spots[3][1]) > 1.0, pulled


@pytest.mark.parametrize("seed", [1, 2])
def test_a_still_spot_joined_to_its_reflection_by_a_faint_neck_is_lost_not_halved(seed: int
                                                                                 ) -> None:
    """A held-out still (rig 66011): a saturated spot and its own wall reflection, as bright,
    20 px apart and joined above the threshold only by a faint neck to one side, were
    measured as one blob, halfway between them (9.9 px off, σ 0.05 px): the centroid lay on
    no lit pixel, so the light joined to it was not found to reach the reflection. Here
    diode 3's reflection lies 18 px along its path from its spot, as bright, with a neck
    bowing 8 px to one side (the centroid of the two lies on no lit pixel): diode 3 is
    lost, flagged as a reflection; without the model it is measured more than 2 px off."""
    paths, beams, places = surface_paths(10)
    heights = 3.0 + 0.15 * places[:, 0] - 0.1 * places[:, 1]
    spots = [(30.0 + 3.0 * (height + 40.0), 20.0 + 26.0 * k, 400.0)
             for k, height in enumerate(heights)]
    x, y, _ = spots[3]
    reflection = (x + 18.0, y, 400.0)
    neck = [(x + along, y + 8.0 * np.sin(np.pi * along / 18.0), 45.0)
            for along in (3.0, 6.0, 9.0, 12.0, 15.0)]
    image = blobs_image([*spots, reflection, *neck], seed, size=300)

    def reflections_px(laser_ids: list[int], points_mm: np.ndarray,
                       normals: np.ndarray) -> np.ndarray:
        pixels = np.full((len(laser_ids), 2), np.nan)
        for row, (laser_id, point) in enumerate(zip(laser_ids, points_mm, strict=True)):
            if laser_id == 3:
                pixels[row] = (30.0 + 3.0 * (point[2] + 40.0) + 18.0, 20.0 + 26.0 * laser_id)
        return pixels

    found = SpotTracker(paths, beams_mm=beams, reflections_px=reflections_px).update(image)
    for k, spot in enumerate(found):
        if k == 3:
            assert spot.flags & LOST and spot.flags & REFLECTION_SUSPECTED, spot
        else:
            assert np.hypot(spot.x_px - spots[k][0], spot.y_px - spots[k][1]) < 0.3, (k, spot)
    halved = SpotTracker(paths, beams_mm=beams).update(image)[3]
    assert np.hypot(halved.x_px - x, halved.y_px - y) > 2.0, halved


def line_ending_at_the_rim(seed: int, spot: tuple[float, float] | None, size: int = 200,
                           end_row: int = 150) -> tuple[np.ndarray, np.ndarray]:
    """A saturated laser line (speckle 10 %) that ends at row `end_row`, where the container's
    rim is a grey stripe, with a bright blob of scattered light on it 4 rows before its end;
    optionally a saturating spot (x, y). The frame and the line's columns on its rows."""
    rng = np.random.default_rng(seed)
    rows, columns = np.mgrid[0:size, 0:size].astype(float)
    line_x = 100.3 + 0.02 * (rows[:, 0] - 100)
    on_line = (rows < end_row) * 600.0 * np.clip(rng.normal(1.0, 0.1, rows.shape), 0, None)
    light = 8.0 + on_line * np.exp(-0.5 * ((columns - line_x[:, None]) / 1.8) ** 2)
    light += 40.0 * ((rows >= end_row) & (rows < end_row + 10))
    light += 900.0 * np.exp(-0.5 * ((columns - line_x[end_row - 4]) ** 2 +
                                    (rows - (end_row - 4)) ** 2) / 3.0**2)
    if spot is not None:
        light += 900.0 * np.exp(-0.5 * ((columns - spot[0]) ** 2 + (rows - spot[1]) ** 2)
                                / 3.0**2)
    noisy = np.round(light + rng.normal(0.0, 2.0, light.shape))
    return np.clip(noisy, 0, 255).astype(np.uint8), line_x[:end_row]


@pytest.mark.parametrize("seed", range(4))
def test_light_where_the_line_ends_is_not_a_hidden_spot_on_it(seed: int) -> None:
    """The real-images bench's held-out rig 64102 (clean): a spot whose path runs along the
    laser line, hidden in the first frames, was acquired on the line 13 px before its end at
    the rim (valid, 43-52 px off for the rest of the video). The line's light is taken away
    as one profile on every row of a window, and a window over the line's end holds rows
    without it. Here a bright blob on the line 4 rows before its end: taken for the hidden
    spot in 10 of 10 draws without the guard; now the spot is lost, and where it is there,
    on the line 40 rows before its end, it is found."""
    path = np.array([[100.3 + 0.02 * (y - 100) - 1.0, y] for y in np.linspace(60, 170, 15)])
    image, line_x = line_ending_at_the_rim(seed, None)
    (hidden,) = SpotTracker({0: path}).update(image, (0, 0), (np.arange(150.0), line_x))
    assert hidden.flags & LOST, hidden
    spot = (100.3 + 0.02 * (110 - 100) + 1.0, 110.0)
    image, line_x = line_ending_at_the_rim(seed, spot)
    (seen,) = SpotTracker({0: path}).update(image, (0, 0), (np.arange(150.0), line_x))
    assert np.hypot(seen.x_px - spot[0], seen.y_px - spot[1]) < 1.0, seen
