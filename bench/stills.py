"""Stills tracked as `sds process` tracks a folder of images: wrong and fabricated spots.

Usage: python bench/stills.py --seeds 7101 7102 ...
For each seed, the demo's rig as built and its real camera's imaging (`draw_demo_rig`, as
`sds demo` and bench/demo_rigs.py draw them), the protocol's table images (one frame per
position: tilts about both axes, the fill levels) rendered with the true rig, each tracked on
its own (`TrackerConfig(stills=True)`, the container's region, red channel) with the true rig:
tracking alone, no calibration error. One row per rig: spots measured of the visible ones,
wrong spots (a measured spot more than 2 px from its diode's truth: another blob taken for
it, or its light pulled off), the largest of those errors, and fabricated spots (measured
while the truth has the diode's spot hidden). Totals end it.
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


def one_rig(seed: int) -> tuple[int, int, list[float], int]:
    """Visible spots, measured ones, each wrong one's error [px], fabricated spots."""
    with tempfile.TemporaryDirectory(prefix="sds-bench-stills-") as folder:
        drawn = draw_demo_rig(load_scenario(DEMO_SCENARIO, {"seed": seed}), Path(folder))
    series = render_surfaces(drawn.true, drawn.surfaces, drawn.scale, drawn.seed,
                             imaging=drawn.imaging)
    rig = drawn.true
    region = Region(*rig.container_region_px(rig.camera, 60))
    ids = [d.laser_id for d in rig.diodes]
    visible, measured, wrong, fabricated = 0, 0, [], 0
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
            measured += 1
            error = float(np.hypot(*(np.array([spot.x_raw_px, spot.y_raw_px])
                                     - truth.spot_exposure_px[k])))
            if error > WRONG_PX:
                wrong.append(error)
    return visible, measured, wrong, fabricated


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[7101, 7102, 7103, 7104])
    args = parser.parse_args()
    print(f"{'seed':>6s} {'measured/visible':>17s} {'wrong':>6s} {'largest px':>10s} "
          f"{'fabricated':>10s}")
    totals = np.zeros(4)
    for seed in args.seeds:
        visible, measured, wrong, fabricated = one_rig(seed)
        largest = f"{max(wrong):10.1f}" if wrong else f"{'-':>10s}"
        print(f"{seed:6d} {measured:8d}/{visible:<8d} {len(wrong):6d} {largest} "
              f"{fabricated:10d}", flush=True)
        totals += (visible, measured, len(wrong), fabricated)
    print(f"total: {int(totals[1])} of {int(totals[0])} visible spots measured, "
          f"{int(totals[2])} wrong (> {WRONG_PX} px), {int(totals[3])} fabricated")


if __name__ == "__main__":
    main()
