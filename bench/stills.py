"""Stills tracked as `sds process` tracks a folder of images: wrong and fabricated spots.

Usage: python bench/stills.py --seeds 7101 7102 ...
For each seed, the demo's rig as built and its real camera's imaging (`draw_demo_rig`, as
`sds demo` and bench/demo_rigs.py draw them), the protocol's table images (one frame per
position: tilts about both axes, the fill levels) rendered with the true rig, each tracked on
its own (`TrackerConfig(stills=True)`, the container's region, red channel) with the true rig:
tracking alone, no calibration error. One row per rig: spots measured of the visible ones,
the median error of the right ones and their error/σ (RMS per axis: an honest σ gives about
1), wrong spots (a measured spot more than 2 px from its diode's truth: another blob taken
for it, or its light pulled off), the largest of those errors, and fabricated spots
(measured while the truth has the diode's spot hidden). Totals end it.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from sds_camera.frame_source import Region, select
from sds_sim.scenario import load_scenario
from sds_sim.tilt_series import render_surfaces
from sds_tracker.spots import is_measured
from sds_tracker.tracker import FrameTracker, TrackerConfig
from sds_workflows.demo import DEMO_SCENARIO
from sds_workflows.demo_rig import draw_demo_rig

WRONG_PX = 2.0
"""A measured spot this far from its diode's truth is not a measurement of it."""
HONEST_BAND = (0.8, 1.25)
"""The error/σ RMS an honest σ gives (issue 45)."""


def one_rig(seed: int) -> tuple[int, list[float], list[float], list[float], int]:
    """Visible spots, each right measured spot's error [px], its error over its σ per axis
    (two values), each wrong spot's error [px], fabricated spots."""
    with tempfile.TemporaryDirectory(prefix="sds-bench-stills-") as folder:
        drawn = draw_demo_rig(load_scenario(DEMO_SCENARIO, {"seed": seed}), Path(folder))
    series = render_surfaces(drawn.true, drawn.surfaces, drawn.scale, drawn.seed,
                             imaging=drawn.imaging)
    rig = drawn.true
    region = Region(*rig.container_region_px(rig.camera, 60))
    ids = [d.laser_id for d in rig.diodes]
    visible, right, normalised, wrong, fabricated = 0, [], [], [], 0
    for image, truth in zip(series.images, series.truths, strict=True):
        tracker = FrameTracker(rig, TrackerConfig(stills=True))
        ((_, spots),), _ = tracker.process(0, select(image, region, "red"),
                                           (region.x, region.y))
        visible += int(truth.visible.sum())
        for spot in spots:
            if not is_measured(spot.flags):
                continue
            k = ids.index(spot.laser_id)
            if not truth.visible[k]:
                fabricated += 1
                continue
            offset = np.array([spot.x_raw_px, spot.y_raw_px]) - truth.spot_exposure_px[k]
            error = float(np.hypot(*offset))
            if error > WRONG_PX:
                wrong.append(error)
            else:
                right.append(error)
                normalised += list(offset / spot.sigma_px)
    return visible, right, normalised, wrong, fabricated


def rms(values: list[float]) -> float:
    """Root mean square."""
    return float(np.sqrt(np.mean(np.square(values))))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[7101, 7102, 7103, 7104])
    args = parser.parse_args()
    print(f"{'seed':>6s} {'measured/visible':>17s} {'right: median px':>16s} "
          f"{'error/σ':>8s} {'wrong':>6s} {'largest px':>10s} {'fabricated':>10s}")
    visible_total, rights, normalised_all, wrongs, fabricated_total = 0, [], [], [], 0
    in_band = 0
    for seed in args.seeds:
        visible, right, normalised, wrong, fabricated = one_rig(seed)
        largest = f"{max(wrong):10.1f}" if wrong else f"{'-':>10s}"
        measured = len(right) + len(wrong)
        print(f"{seed:6d} {measured:8d}/{visible:<8d} {np.median(right):16.3f} "
              f"{rms(normalised):8.2f} {len(wrong):6d} {largest} {fabricated:10d}", flush=True)
        visible_total += visible
        rights += right
        normalised_all += normalised
        in_band += int(HONEST_BAND[0] <= rms(normalised) <= HONEST_BAND[1])
        wrongs += wrong
        fabricated_total += fabricated
    print(f"total: {len(rights) + len(wrongs)} of {visible_total} visible spots measured, "
          f"right ones' median error {np.median(rights):.3f} px, error/σ "
          f"{rms(normalised_all):.2f} (rigs within {HONEST_BAND[0]}-{HONEST_BAND[1]}: "
          f"{in_band} of {len(args.seeds)}), {len(wrongs)} wrong (> {WRONG_PX} px), "
          f"{fabricated_total} fabricated")


if __name__ == "__main__":
    main()
