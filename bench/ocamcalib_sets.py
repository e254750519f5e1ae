"""The project's Scaramuzza fit against OCamCalib on the seven ocamcalib_urban sets.

Usage: python bench/ocamcalib_sets.py [--data ../shared/data/ocamcalib_urban]
For each set: OCamCalib's RMS reprojection error (ALL1: original pipeline; ALL2: with Urban's
sub-pixel corners; imgBack: the GUI session's result), the project's RMS from the images alone
(`sds calibrate camera` path: detection, fit, outlier re-detection) and from OCamCalib's own
ALL2 corners (the fit alone, same points), the centre difference and the run time.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from sds_recon.calibration.board import BoardView, Checkerboard
from sds_recon.calibration.camera_calibration import calibrate_camera
from sds_recon.calibration.intrinsics import calibrate_scaramuzza

REPO = Path(__file__).resolve().parents[1]
SETS = ["imgBack", "Fisheye1", "Fisheye2", "MiniOmni", "VMRImage", "Ladybug", "KaidanOmni"]


def reference(folder: Path, name: str, run: str) -> dict | None:
    if name == "imgBack":  # one GUI session, no ALL1/ALL2 test runs
        file = folder / name / "reference_ocamcalib.json" if run == "ALL2" else None
    else:
        file = folder / name / f"reference_ocamcalib_{run}.json"
    return json.loads(file.read_text()) if file is not None else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path,
                        default=REPO.parent / "shared" / "data" / "ocamcalib_urban")
    args = parser.parse_args()
    print(f"{'set':<11}{'images':>7}{'points':>7}{'ALL1 rms':>9}{'ALL2 rms':>9}{'ours rms':>9}"
          f"{'ratio':>7}{'fit-only':>9}{'centre Δ px':>12}{'fixed':>6}{'time s':>7}")
    for name in SETS:
        all2, all1 = reference(args.data, name, "ALL2"), reference(args.data, name, "ALL1")
        board = all2["board"]
        checkerboard = Checkerboard(board["n_sq_x"] + 1, board["n_sq_y"] + 1, board["dX"])
        start = time.perf_counter()
        run = calibrate_camera([args.data / name / image for image in all2["processed_images"]],
                               checkerboard, "scaramuzza")
        seconds = time.perf_counter() - start
        points = np.column_stack([board["Xt"], board["Yt"], np.zeros(len(board["Xt"]))])
        theirs = [BoardView(image, np.column_stack([all2["corners"][image]["col_1based"],
                                                    all2["corners"][image]["row_1based"]]) - 1,
                            points) for image in all2["processed_images"]]
        camera = run.calibration.camera
        fit_only = calibrate_scaramuzza(theirs, camera.width_px, camera.height_px)
        model = all2["ocam_model_matlab"]
        centre = np.hypot(camera.x0_px - (model["yc"] - 1), camera.y0_px - (model["xc"] - 1))
        rms2 = all2["recomputed_reprojection"]["overall_rms_px"]
        rms1 = "-" if all1 is None else f'{all1["recomputed_reprojection"]["overall_rms_px"]:.3f}'
        ours = run.calibration.rms_px
        print(f"{name:<11}{len(run.calibration.views):>7}"
              f"{sum(len(v.image_points) for v in run.calibration.views):>7}{rms1:>9}"
              f"{rms2:>9.3f}{ours:>9.3f}{ours / rms2:>7.2f}{fit_only.rms_px:>9.3f}{centre:>12.2f}"
              f"{len(run.corrections):>6}{seconds:>7.1f}")


if __name__ == "__main__":
    main()
