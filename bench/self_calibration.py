"""Self-calibration against the seed's beam-only calibration over random true rigs.

Each trial: a random diode layout (not stelium.yaml's), beams leaning (σ 0.6°, up to 3°), the
camera turned up to ±2° about each axis and moved ±5 mm in height, wall reflections; eight 4K
tilt images about one axis calibrate the nominal rig file; an unseen series about the other
axis is tracked and fitted with the result; the same rig is also calibrated with three tilts
about the second axis added (the two-axis protocol). Prints one row per rig and the summary.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from sds_workflows.calibration_trial import SECOND_AXIS, GeometryErrors, trial

RIG = Path(__file__).resolve().parents[1] / "config" / "rigs" / "stelium.yaml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--rigs", type=int, default=20)
    parser.add_argument("--first-seed", type=int, default=0)
    args = parser.parse_args()
    rows = []
    print("seed  wrong/spots  calibrated  unidentified  camera err deg (sigma)  cam mm  "
          "beam max deg  plane deg (sigma)  unseen tilt deg / RMSE mm: self | beam-only  "
          "drop RMSE mm, missed  two-axis: camera deg (sigma), beam max deg (its sigma), "
          "plane deg (sigma)  s")
    for seed in range(args.first_seed, args.first_seed + args.rigs):
        start = time.perf_counter()
        r = trial(seed, RIG, second_axis=True)
        one, two = r["geometry"], r["two_axis"]
        # NaN: the plane's turn about the line was not determined and kept from the rig file
        plane_sigma = "kept" if np.isnan(one.line_plane_sigma_deg) else \
            f"{one.line_plane_sigma_deg:.3f}"
        rows.append(r)
        print(f"{seed:>4}  {r['wrong']:>3}/{r['spots']:<6}  {len(r['calibrated']):>10}  "
              f"{len(r['unidentified']):>12}  "
              f"{np.abs(one.camera_deg).max():>6.3f} ({one.camera_sigma_deg.max():.3f})"
              f"  {np.abs(one.camera_mm).max():>6.3f}  "
              f"{max(one.beams_deg.values()):>12.3f}  "
              f"{one.line_plane_deg:>9.3f} ({plane_sigma})  "
              f"{r['self'].tilt_error_deg:.3f} / {r['self'].heights.rmse_mm:.3f} | "
              f"{r['beam_only'].tilt_error_deg:.3f} / {r['beam_only'].heights.rmse_mm:.3f}"
              f"  {r['drop'].heights.rmse_mm:.3f}, {r['drop'].missed}/{r['drop'].spots}"
              f" ({r['drop'].rejected} rejected)  {np.abs(two.camera_deg).max():.4f} "
              f"({two.camera_sigma_deg.max():.4f}), {max(two.beams_deg.values()):.4f} "
              f"({two.beams_sigma_deg[max(two.beams_deg, key=two.beams_deg.get)]:.4f}), "
              f"{two.line_plane_deg:.4f} ({two.line_plane_sigma_deg:.4f})"
              f"   {time.perf_counter() - start:.1f}", flush=True)
    beams = np.concatenate([list(r["geometry"].beams_deg.values()) for r in rows])
    two_beams = np.concatenate([list(r["two_axis"].beams_deg.values()) for r in rows])
    print(f"\n{len(rows)} rigs: wrong identities {sum(r['wrong'] for r in rows)}, "
          f"unidentified diodes {sum(len(r['unidentified']) for r in rows)}")
    print(f"camera angle error max "
          f"{max(np.abs(r['geometry'].camera_deg).max() for r in rows):.3f} deg, position "
          f"{max(np.abs(r['geometry'].camera_mm).max() for r in rows):.3f} mm; "
          f"beams: median {np.median(beams):.3f} deg, 95 % {np.percentile(beams, 95):.3f}, "
          f"max {beams.max():.3f}; line plane: max "
          f"{max(r['geometry'].line_plane_deg for r in rows):.3f} deg; "
          f"weakly determined in {sum(bool(r['weak']) for r in rows)} rigs")
    print(f"two-axis protocol (+{len(SECOND_AXIS)} tilts about Y): camera angle error max "
          f"{max(np.abs(r['two_axis'].camera_deg).max() for r in rows):.4f} deg, position "
          f"{max(np.abs(r['two_axis'].camera_mm).max() for r in rows):.3f} mm; beams: median "
          f"{np.median(two_beams):.4f} deg, max {two_beams.max():.4f}; line plane max "
          f"{max(r['two_axis'].line_plane_deg for r in rows):.4f} deg")
    for label, protocol in (("one-axis", [r["geometry"] for r in rows]),
                            ("two-axis", [r["two_axis"] for r in rows])):
        camera, beams, plane = np.max([worst_ratios(g) for g in protocol], axis=0)
        print(f"{label} error/sigma, max over the rigs (honest sigmas stay near 3 or below): "
              f"camera angles {camera:.1f}, beams {beams:.1f}, line plane {plane:.1f}")
    for key in ("self", "beam_only"):
        tilt = [r[key].tilt_error_deg for r in rows]
        rmse = [r[key].heights.rmse_mm for r in rows]
        print(f"unseen series, {key}: tilt error median {np.median(tilt):.3f} max "
              f"{np.max(tilt):.3f} deg; height RMSE median {np.median(rmse):.3f} max "
              f"{np.max(rmse):.3f} mm (points with sigma <= 0.1 mm: "
              f"{sum(r[key].heights.precise for r in rows)} of "
              f"{sum(r[key].heights.points for r in rows)}); error/sigma RMS max "
              f"{max(r[key].heights.normalised_rms for r in rows):.2f}")
    drops = [r["drop"] for r in rows]
    print(f"1 g drop, 30 frames: height RMSE median "
          f"{np.median([d.heights.rmse_mm for d in drops]):.3f} max "
          f"{max(d.heights.rmse_mm for d in drops):.3f} mm, error/sigma RMS max "
          f"{max(d.heights.normalised_rms for d in drops):.2f}; spots missed "
          f"{sum(d.missed for d in drops)} of {sum(d.spots for d in drops)}, rejected by the "
          f"fits {sum(d.rejected for d in drops)}")


def worst_ratios(g: GeometryErrors) -> tuple[float, float, float]:
    """Largest |error| / σ of the camera's angles, the beams and the line plane (a value kept
    from the rig file has no σ and is left out)."""

    def worst(errors: list[float], sigmas: list[float]) -> float:
        ratio = np.abs(np.asarray(errors, float)) / np.asarray(sigmas, float)
        return float(np.max(ratio[np.isfinite(ratio)], initial=0.0))

    laser_ids = list(g.beams_deg)
    return (worst(list(g.camera_deg), list(g.camera_sigma_deg)),
            worst([g.beams_deg[i] for i in laser_ids], [g.beams_sigma_deg[i] for i in laser_ids]),
            worst([g.line_plane_deg], [g.line_plane_sigma_deg]))


if __name__ == "__main__":
    main()
