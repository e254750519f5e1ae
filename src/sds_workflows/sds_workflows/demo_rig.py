"""`sds demo`'s rig as built and its calibration by docs/rig.md's protocol, as a user does it.

The demo's rig file is the StELIUM rig as designed (vertical beams, the camera where the
drawing puts it, the emitters' tolerance declared, the camera's readout as measured). The
simulator renders a rig *as built* from it, seeded: beams leaning, the camera turned and
moved, emitters off by their tolerance, the true camera's intrinsics off its file by their σ
and its readout off the measured one, a real camera's imaging (`sds_sim.imaging`, every
effect drawn in its range). The user's steps then run on what such a user has: `sds calibrate
plan` on the rig file writes the protocol's surfaces CSV, a burst of images at each table
position is rendered at the liquid's true pose (the table read to the seed's accuracy; the
speckle new in every frame), and `sds calibrate rig` on those images writes the calibrated
rig file the drop is measured with.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from sds_model.camera.rolling_shutter import RollingShutter
from sds_model.rig import Rig, Tolerances, load_rig, save_rig
from sds_recon.calibration.lasers import KnownSurface
from sds_recon.calibration.rig_calibration import RigCalibration
from sds_sim.imaging import draw_imaging, merged
from sds_sim.scenario import Scenario
from sds_sim.tilt_series import ReadingErrors, render_surfaces, true_surfaces
from sds_sim.true_rig import RigErrors, camera_as_calibrated, true_rig

from sds_workflows.calibration_plan import plan_protocol, write_protocol
from sds_workflows.calibration_trial import geometry_errors
from sds_workflows.rig_calibration import FRAMES_PER_STILL, IMAGE_THREADS, calibrate_rig

RIG_ERRORS = RigErrors(emitter_sigma_mm=0.3)
"""How the demo's rig as built departs from its file (beams, camera pose, line plane: the
simulator's defaults; emitters: a 3D-printed holder's tenths of a mm)."""
DECLARED_EMITTER_MM = 0.3
"""The emitters' tolerance the demo's rig file declares (tolerances.emitter_mm)."""
READINGS = ReadingErrors(about_axis_deg=0.5, across_deg=0.15, level_deg=0.05, offset_mm=0.05)
"""How the tilt table is read: the seed's table ("0.5 deg accuracy") about its axis, the other
angle kept close to 0, a spirit level on level frames, fill levels from a measured volume."""
READOUT_S = 0.020
"""The rolling shutter's readout the demo's rig file states (as `sds camera readout` measured
it; a GoPro at 4K reads its rows over a few tens of ms)."""
READOUT_SIGMA_S = 0.0003
"""σ of that measurement: the true camera's readout is drawn off it by this much."""
PNG_FAST = [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_SUB,
            cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY]
"""How the table's images are written: the left-neighbour filter and Huffman codes only, no
search for repeats (a 4K table image: 0.21 s of CPU and 13.7 MB, against 0.52 s and 15.1 MB
at zlib's fastest level with libpng's filter choice; lossless either way)."""
STREAM = 48
"""The second key of the demo rig's random stream (the first is the scenario's seed)."""


@dataclass(frozen=True)
class DemoRig:
    """The demo's rig: the true one the simulator renders, the scenario overrides of its
    imaging and rolling shutter, the files the user's steps wrote, and the calibration (the
    calibrated rig carries its report's record: model check, unseen surfaces' σ)."""

    true: Rig
    scenario_overrides: dict[str, dict[str, Any]]
    surfaces_csv: Path
    images: list[Path]   # FRAMES_PER_STILL per table position, in the surfaces' order
    calibrated_file: Path
    calibrated: Rig
    result: RigCalibration
    planned_tilt_sigma_deg: float

    def against_truth(self) -> list[str]:
        """The calibrated rig against the true one, each error beside the σ the calibration
        states for it (`calibration_trial.geometry_errors`): camera turn and position, the
        beams' directions, the line plane."""
        errors = geometry_errors(self.calibrated, self.true, self.result)
        beam_error = np.array(list(errors.beams_deg.values()))
        beam_sigma = np.array([errors.beams_sigma_deg[i] for i in errors.beams_deg])
        lines = [
            "camera turned   error [deg] " + ", ".join(
                f"{e:+.3f} ± {s:.3f}" for e, s in zip(errors.camera_deg, errors.camera_sigma_deg,
                                                     strict=True)),
            "camera position error [mm]  " + ", ".join(
                f"{e:+.3f} ± {s:.3f}" for e, s in zip(errors.camera_mm, errors.camera_sigma_mm,
                                                     strict=True)),
            f"beams           {len(beam_error)} of {len(self.true.diodes)} calibrated: "
            f"direction error RMS {np.sqrt(np.mean(beam_error**2)):.3f} deg, stated σ RMS "
            f"{np.sqrt(np.mean(beam_sigma**2)):.3f} deg, worst {beam_error.max():.3f} deg"]
        if np.isfinite(errors.line_plane_deg):
            lines.append(f"line plane      normal error {errors.line_plane_deg:.3f} deg, stated "
                         f"σ {errors.line_plane_sigma_deg:.3f} deg")
        return lines


@dataclass(frozen=True)
class DrawnRig:
    """The demo's rig as built before any image: the true rig and the true surfaces the table
    gives, the scenario overrides of its imaging and rolling shutter, and the user's files so
    far (the rig file as designed, the protocol's surfaces CSV)."""

    true: Rig
    scenario_overrides: dict[str, dict[str, Any]]
    imaging: dict[str, dict[str, Any]]
    nominal: Rig
    surfaces_csv: Path
    surfaces: list[KnownSurface]   # the liquid's true pose at each table position
    planned_tilt_sigma_deg: float
    scale: float
    seed: int


def draw_demo_rig(scenario: Scenario, folder: Path) -> DrawnRig:
    """Draw the scenario's rig as built (seeded by the scenario's seed), write the user's rig
    file and plan the protocol in `folder`: everything the drop's simulation needs."""
    rng = np.random.default_rng((scenario.seed, STREAM))
    base = scenario.rig
    # The rig file as the user writes it: the camera inline (the GoPro's file and the
    # readout measured), the emitters' tolerance declared.
    designed = replace(base, camera_file=None,
                       camera_shutter=RollingShutter(READOUT_S, "top_to_bottom"),
                       tolerances=Tolerances(emitter_mm=DECLARED_EMITTER_MM))
    true = true_rig(designed, RIG_ERRORS, rng)
    true = replace(true, camera=camera_as_calibrated(base.camera, base.camera_sigma, 1.0, rng))
    readout_s = float(READOUT_S + rng.normal(0.0, READOUT_SIGMA_S))
    imaging = draw_imaging(rng)
    rig_file = save_rig(designed, folder / "rig.yaml", comment=(
        "The demo's rig file as designed (sds demo): the StELIUM rig, the GoPro's camera file "
        "inline with its readout as measured, the emitters' tolerance declared."))
    nominal = load_rig(rig_file)
    steps = plan_protocol(nominal, READINGS.accuracy())
    surfaces_csv = folder / "surfaces.csv"
    write_protocol(steps[-1], surfaces_csv)
    surfaces = true_surfaces(steps[-1].surfaces, READINGS, rng)
    overrides = merged({"sensor": {"readout_s": readout_s, "readout_direction":
                                   designed.camera_shutter.direction}}, imaging)
    return DrawnRig(true, overrides, imaging, nominal, surfaces_csv, surfaces,
                    steps[-1].worst_tilt_deg, scenario.scale, scenario.seed)


def calibrate_demo_rig(drawn: DrawnRig, folder: Path) -> DemoRig:
    """Render the table's images of the drawn rig into `folder` and calibrate the rig from
    them as `sds calibrate rig` does."""
    series = render_surfaces(drawn.true, drawn.surfaces, drawn.scale, drawn.seed,
                             frames=FRAMES_PER_STILL, imaging=drawn.imaging)
    shots = {folder / f"table_{index:02d}_{shot}.png": frame
             for index, image in enumerate(series.images)
             for shot, frame in enumerate([image, *series.repeats[index]])}
    with ThreadPoolExecutor(IMAGE_THREADS) as pool:
        written = list(pool.map(lambda shot: cv2.imwrite(str(shot[0]), shot[1], PNG_FAST),
                                shots.items()))
    images = list(shots)
    for path, ok in zip(images, written, strict=True):
        if not ok:
            raise OSError(f"{path}: the table image could not be written")
    calibrated_file = folder / "rig_calibrated.yaml"
    calibrated, result = calibrate_rig(drawn.nominal, images, drawn.surfaces_csv,
                                       calibrated_file,
                                       "`sds demo` (sds calibrate rig on the table's images)")
    return DemoRig(drawn.true, drawn.scenario_overrides, drawn.surfaces_csv, images,
                   calibrated_file, calibrated, result, drawn.planned_tilt_sigma_deg)


def demo_rig(scenario: Scenario, folder: Path) -> DemoRig:
    """Draw the scenario's rig as built, write the user's rig file, plan the protocol, render
    the table's images and calibrate the rig from them, all in `folder`."""
    return calibrate_demo_rig(draw_demo_rig(scenario, folder), folder)
