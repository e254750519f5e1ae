"""`sds calibrate camera|rig|plan|line-plane|lasers`: the camera, the whole rig, its protocol,
the line laser's plane, or the beams alone."""

from __future__ import annotations

import argparse
from pathlib import Path

from sds_cli.commands import (
    CommandError,
    add_overwrite,
    existing_file,
    output_file,
    positive_float,
    refuse_existing,
)


def add_board_arguments(parser: argparse.ArgumentParser) -> None:
    """--board and --square: the checkerboard (sds_recon.calibration.board.Checkerboard)."""
    parser.add_argument("--board", required=True, metavar="COLSxROWS",
                        help="inner corners per row x per column, e.g. 9x6")
    parser.add_argument("--square", type=positive_float, required=True, metavar="MM",
                        help="checkerboard square size [mm]")


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds calibrate` and its targets."""
    parser = commands.add_parser("calibrate",
                                 help="calibrate the camera, the whole rig, or the beams alone")
    targets = parser.add_subparsers(title="targets", required=True, metavar="TARGET")
    camera = targets.add_parser(
        "camera", help="intrinsic calibration from checkerboard images",
        description="Find the checkerboard's inner corners in every image (sub-pixel), fit the "
                    "model, and write the camera file and a report (JSON, text, residual plot).",
    )
    camera.add_argument("--model", choices=["pinhole", "scaramuzza"], required=True,
                        help="pinhole + Brown-Conrady, or Scaramuzza's omnidirectional model")
    camera.add_argument("--images", nargs="+", type=existing_file, required=True,
                        help="image files (all the same size)")
    add_board_arguments(camera)
    camera.add_argument("--out", type=output_file, default=Path("camera.yaml"),
                        help="camera file to write; the report goes beside it")
    add_overwrite(camera)
    camera.set_defaults(run=run_camera, command="calibrate camera")
    lasers = targets.add_parser(
        "lasers", help="laser beams and the line laser's plane from images of known surfaces",
        description="Each spot seen on a known flat surface (level or tilted) is a point of its "
                    "beam; every beam (and the line laser's plane) is fitted to its points by "
                    "least squares, and an updated rig file is written with a report.")
    lasers.add_argument("--rig", type=existing_file, required=True, help="the rig file as designed")
    lasers.add_argument("--spots", type=existing_file, required=True,
                        help="CSV: frame, laser_id, x_px, y_px[, visible] (full-frame pixels)")
    lasers.add_argument("--surfaces", type=existing_file, required=True,
                        help="CSV: frame, tilt_x_deg, tilt_y_deg[, offset_mm]")
    lasers.add_argument("--line", type=existing_file,
                        help="NPZ with line_x_px (frames x image rows)")
    lasers.add_argument("--fit-emitters", action="store_true",
                        help="also move each emitter onto its fitted beam")
    lasers.add_argument("--out", type=output_file, required=True, help="rig file to write")
    add_overwrite(lasers)
    lasers.set_defaults(run=run_lasers, command="calibrate lasers")
    rig = targets.add_parser(
        "rig", help="self-calibrate camera pose, beams and line plane from images of known "
                    "surfaces",
        description="Find every spot in each image without trusting the rig file's beams, "
                    "identify the diodes over the whole series (a beam through its emitter), "
                    "fit camera pose and beams jointly, then the line laser's plane through "
                    "the fitted camera; write the calibrated rig with uncertainties, a report "
                    "and one overlay per image.")
    rig.add_argument("--rig", type=existing_file, required=True, help="the rig file as designed")
    source = rig.add_mutually_exclusive_group(required=True)
    source.add_argument("--images", type=existing_file, nargs="+",
                        help="images of known surfaces (image k is frame k of --surfaces), "
                             "or a burst of the same number per surface in that order (the "
                             "first its image, the others its repeats)")
    source.add_argument("--video", type=existing_file,
                        help="video of the tilt table: its still stretches (0.5 s or more), "
                             "in order, are the frames of --surfaces")
    rig.add_argument("--surfaces", type=existing_file, required=True,
                     help="CSV: frame, tilt_x_deg, tilt_y_deg[, offset_mm]")
    rig.add_argument("--out", type=output_file, required=True, help="calibrated rig file to write")
    rig.add_argument("--cone-deg", type=positive_float, default=3.0,
                     help="farthest a beam may lean from the rig file's direction [deg]")
    rig.add_argument("--camera-turn-deg", type=positive_float, default=2.0,
                     help="farthest the camera may be turned from the rig file [deg]")
    rig.add_argument("--fit-emitters", action="store_true",
                     help="also fit each emitter's position across its beam")
    add_overwrite(rig)
    rig.set_defaults(run=run_rig, command="calibrate rig")
    planned = targets.add_parser(
        "plan", help="which known surfaces to record for `sds calibrate rig`, and what they "
                     "will give",
        description="From the rig file (its tolerances as priors) and how well each surface "
                    "is read, predict every parameter's σ and the tilt and height σ of unseen "
                    "surfaces for the seed's tilt series, then add the candidate surfaces "
                    "(tilts about Y, other fill levels) that bring an unmet goal closest.")
    planned.add_argument("--rig", type=existing_file, required=True,
                         help="the rig file as designed, with its tolerances")
    planned.add_argument("--candidates", type=existing_file,
                         help="surfaces CSV of candidate surfaces (default: tilts about Y of "
                              "12.5, 22.5, 32.5 deg and fill levels every 10 mm up to where "
                              "a 35 deg tilt reaches the wall, inside the container)")
    planned.add_argument("--table-sigma-deg", type=positive_float, default=0.5 / 3**0.5,
                         help="σ of a tilted frame's angle about the table's axis [deg] "
                              "(default: ±0.5 deg, uniform)")
    planned.add_argument("--table-across-sigma-deg", type=positive_float,
                         help="σ of its other angle, across the table's axis [deg] (default: "
                              "--table-sigma-deg)")
    planned.add_argument("--level-sigma-deg", type=positive_float, default=0.05,
                         help="σ of a level frame's angles [deg] (a spirit level)")
    planned.add_argument("--fill-sigma-mm", type=positive_float, default=0.05,
                         help="σ of a fill level [mm] (a measured volume)")
    planned.add_argument("--out", type=output_file,
                         help="write the planned protocol as a surfaces CSV")
    add_overwrite(planned)
    planned.set_defaults(run=run_plan, command="calibrate plan")
    plane = targets.add_parser(
        "line-plane", help="camera and line laser plane from a checkerboard crossed by the line",
        description="Calibrate the camera on the board, find the red line's centre per row "
                    "inside each board, put it on that board's plane and fit one plane to all "
                    "(camera frame, n.X + d = 0, mm); write it as JSON with its residuals.")
    plane.add_argument("--images", nargs="+", type=existing_file, required=True,
                       help="colour images, one board pose each, the line crossing the board")
    add_board_arguments(plane)
    plane.add_argument("--model", choices=["pinhole", "scaramuzza"], default="pinhole",
                       help="camera model calibrated on the board (default pinhole)")
    plane.add_argument("--out", type=output_file, required=True, help="JSON file to write")
    add_overwrite(plane)
    plane.set_defaults(run=run_line_plane, command="calibrate line-plane")


def run_line_plane(args: argparse.Namespace) -> int:
    """The line laser's plane in the camera frame, as JSON."""
    import json

    import numpy as np
    from sds_recon.calibration.board import Checkerboard
    from sds_workflows.line_plane_calibration import calibrate_line_plane, line_plane_report

    refuse_existing(args.out, args.overwrite)
    result = calibrate_line_plane(sorted(args.images),
                                  Checkerboard.parse(args.board, args.square), args.model)
    args.out.write_text(json.dumps(line_plane_report(result), indent=2) + "\n")
    residuals = result.residuals_mm()
    normal = result.plane.normal
    print(f"line plane (camera frame): n = [{normal[0]:.6f}, {normal[1]:.6f}, {normal[2]:.6f}], "
          f"d = {-normal @ result.plane.point_mm:.3f} mm; {len(residuals)} points, "
          f"mean |residual| {np.mean(np.abs(residuals)):.3f} mm; camera RMS "
          f"{result.camera_run.calibration.rms_px:.3f} px")
    print(f"wrote {args.out}")
    return 0


def run_rig(args: argparse.Namespace) -> int:
    """The self-calibrated rig file, its report and overlays."""
    from sds_model.rig import load_rig
    from sds_recon.calibration.rig_calibration import CalibrationSettings
    from sds_workflows.rig_calibration import calibrate_rig

    refuse_existing(args.out, args.overwrite)
    rig = load_rig(args.rig)
    settings = CalibrationSettings(cone_deg=args.cone_deg, camera_turn_deg=args.camera_turn_deg,
                                   fit_emitters=args.fit_emitters)
    calibrate_rig(rig, args.images or [args.video], args.surfaces, args.out,
                  f"`sds calibrate rig` from {args.rig}", settings)
    stem = args.out.with_suffix("")
    print(Path(f"{stem}.report.txt").read_text(), end="")
    print(f"wrote {args.out} and its report, {stem}.report.html")
    return 0


def run_plan(args: argparse.Namespace) -> int:
    """The planned protocol: a table of predicted σ, and its surfaces CSV with --out."""
    from sds_model.rig import load_rig
    from sds_recon.calibration.lasers import Accuracy
    from sds_workflows.calibration_plan import (
        plan_protocol,
        plan_text,
        shares_text,
        what_if_text,
        what_would_meet_the_goals,
        write_protocol,
    )

    if args.out is not None:
        refuse_existing(args.out, args.overwrite)
    for name in ("table_sigma_deg", "table_across_sigma_deg", "level_sigma_deg",
                 "fill_sigma_mm"):
        if getattr(args, name) is not None and not getattr(args, name) > 0:
            raise CommandError(f"--{name.replace('_', '-')} must be positive")
    rig = load_rig(args.rig)
    accuracy = Accuracy(args.table_sigma_deg, args.table_across_sigma_deg, args.level_sigma_deg,
                        args.fill_sigma_mm)
    steps = plan_protocol(rig, accuracy, args.candidates)
    print(plan_text(steps))
    if not steps[-1].meets_goals():
        print(shares_text(steps[-1]))
        print(what_if_text(what_would_meet_the_goals(rig, accuracy, steps[-1])))
    if args.out is not None:
        write_protocol(steps[-1], args.out)
        print(f"wrote {args.out} ({len(steps[-1].surfaces)} surfaces)")
    return 0


def run_lasers(args: argparse.Namespace) -> int:
    """Beams (and line plane) fitted to spots on known surfaces: rig file and report."""
    import json

    from sds_model.rig import load_rig, save_rig
    from sds_recon.calibration.laser_files import calibrate_lasers, report_text

    refuse_existing(args.out, args.overwrite)
    rig = load_rig(args.rig)
    calibrated, report = calibrate_lasers(rig, args.spots, args.surfaces, args.line,
                                          args.fit_emitters)
    text = report_text(report)
    comment = f"Calibrated by `sds calibrate lasers` from {args.rig}:\n{text}"
    save_rig(calibrated, args.out, comment=comment)
    report_path = args.out.with_suffix(".report.json")
    report_path.write_text(json.dumps(report, indent=2) + "\n")
    print(text)
    print(f"wrote {args.out} and {report_path}")
    return 0


def run_camera(args: argparse.Namespace) -> int:
    """Intrinsic calibration: camera file and report."""
    from sds_model.camera import save_camera
    from sds_recon.calibration.board import Checkerboard
    from sds_recon.calibration.camera_calibration import calibrate_camera
    from sds_recon.calibration.report import report_content, report_text, write_report

    refuse_existing(args.out, args.overwrite)
    board = Checkerboard.parse(args.board, args.square)
    run = calibrate_camera(sorted(args.images), board, args.model)
    unconverged = "" if run.calibration.converged else "THE FIT DID NOT CONVERGE. "
    camera_path = save_camera(run.calibration.camera, args.out, comment=(
        f"{unconverged}Calibrated by `sds calibrate camera --model {args.model}` from "
        f"{len(run.calibration.views)} images of a {args.board} board, {args.square:g} mm squares: "
        f"RMS reprojection error {run.calibration.rms_px:.3f} px."))
    paths = write_report(run, camera_path.parent, camera_path.stem)
    print(report_text(report_content(run)))
    print(f"wrote {camera_path}, {paths['json']}, {paths['text']}, {paths['plot']}")
    return 0
