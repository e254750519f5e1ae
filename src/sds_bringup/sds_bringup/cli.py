"""The `sds` command: one entry point, one subcommand per job."""

from __future__ import annotations

import argparse
import importlib.metadata
import os
import sys
from pathlib import Path

# FFmpeg and OpenCV print their own lines for a corrupt video; the commands say it in one.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")

from sds_bringup import analyze, clock_link, offline, recording
from sds_bringup.graph import GraphFileError, apply_overrides, composed, load_graph
from sds_bringup.launcher import Launcher
from sds_bringup.paths import CONFIG
from sds_bringup.ros_env import graph_environment, pick_domain_id


def _add_graph(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser(
        "graph", help="start the nodes of a graph file as processes",
        description="Start a graph (config/graphs/*.yaml); Ctrl-C or SIGTERM stops every node.",
    )
    parser.add_argument("graph_file", type=Path, help="a graph file, e.g. config/graphs/drop.yaml")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="NODE.PARAM=VALUE", help="override a node parameter (YAML value)")
    parser.add_argument("--compose", action="store_true",
                        help="host every node in one process instead of one process each")
    parser.add_argument("--domain-id", type=int, default=None,
                        help="ROS_DOMAIN_ID for the graph (default: a random one in 1..101)")
    parser.set_defaults(run=_run_graph)


def _run_graph(args: argparse.Namespace) -> int:
    try:
        entries = apply_overrides(load_graph(args.graph_file), args.overrides)
    except GraphFileError as error:
        print(f"sds graph: {error}", file=sys.stderr)
        return 2
    if args.compose:
        entries = composed(entries)
    domain_id = pick_domain_id() if args.domain_id is None else args.domain_id
    print(f"sds graph: {args.graph_file} on ROS_DOMAIN_ID={domain_id} (localhost only)")
    return Launcher(entries, graph_environment(domain_id)).run()


def _add_demo(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser(
        "demo", help="simulate a drop, measure it with the whole graph, compare with the truth",
        description="Simulate a 4.7 s drop (config/scenarios/drop_4p7s.yaml), run the whole "
                    "chain on it as node processes (camera, tracker, reconstruction, Arduino "
                    "bridge on a pseudo-terminal, recorder, Rerun), analyse the recording and "
                    "print the results next to the simulator's truth.",
    )
    parser.add_argument("--out", type=Path, default=Path("demo_output"),
                        help="the demo's own folder (rewritten on each run)")
    parser.add_argument("--seconds", type=float, help="simulated duration [s] (default 4.7)")
    parser.set_defaults(run=_run_demo)
    run = commands.add_parser(
        "run", help="a video or a live camera through the whole graph, then the analysis",
        description="Run the whole chain (config/graphs/drop.yaml + arduino.yaml + view.yaml) "
                    "on a recorded video or a live camera; Ctrl-C stops a live run.")
    source = run.add_mutually_exclusive_group(required=True)
    source.add_argument("--video", help="video file")
    source.add_argument("--camera", help="camera device, e.g. /dev/video0")
    run.add_argument("--rig", type=Path, required=True, help="the rig file")
    run.add_argument("--out", type=Path, default=Path("run_output"),
                     help="folder for the recording, Rerun file, results and report")
    run.add_argument("--port", help="the Arduino's serial port (default: arduino.yaml's)")
    run.add_argument("--gravity", type=float, help="gravity for the theory [m/s²]")
    run.add_argument("--overwrite", action="store_true",
                     help="replace the recording and results of an earlier run in --out")
    run.set_defaults(run=_run_run)


def _run_demo(args: argparse.Namespace) -> int:
    from sds_bringup.demo import run_demo

    return run_demo(args.out, args.seconds)


def _run_run(args: argparse.Namespace) -> int:
    from sds_bringup.demo import run_live

    return run_live(args.video or args.camera, args.rig, args.out, args.port, args.gravity,
                    args.overwrite)


def _add_overwrite(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --out")


def _refused(command: str, path: Path, overwrite: bool, what: str = "exists") -> bool:
    """True, with one line on stderr, when `path` exists and `--overwrite` was not given."""
    if path.exists() and not overwrite:
        print(f"sds {command}: {path} {what} (another --out, or --overwrite)", file=sys.stderr)
        return True
    return False


def _add_board_arguments(parser: argparse.ArgumentParser) -> None:
    """--board and --square: the checkerboard (sds_recon.calibration.board.Checkerboard)."""
    parser.add_argument("--board", required=True, metavar="COLSxROWS",
                        help="inner corners per row x per column, e.g. 9x6")
    parser.add_argument("--square", type=float, required=True, metavar="MM",
                        help="checkerboard square size [mm]")


def _add_calibrate(commands: argparse._SubParsersAction) -> None:
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
    camera.add_argument("--images", nargs="+", type=Path, required=True,
                        help="image files (all the same size)")
    _add_board_arguments(camera)
    camera.add_argument("--out", type=Path, default=Path("camera.yaml"),
                        help="camera file to write; the report goes beside it")
    _add_overwrite(camera)
    camera.set_defaults(run=_run_calibrate_camera)
    lasers = targets.add_parser(
        "lasers", help="laser beams and the line laser's plane from images of known surfaces",
        description="Each spot seen on a known flat surface (level or tilted) is a point of its "
                    "beam; every beam (and the line laser's plane) is fitted to its points by "
                    "least squares, and an updated rig file is written with a report.")
    lasers.add_argument("--rig", type=Path, required=True, help="the rig file as designed")
    lasers.add_argument("--spots", type=Path, required=True,
                        help="CSV: frame, laser_id, x_px, y_px[, visible] (full-frame pixels)")
    lasers.add_argument("--surfaces", type=Path, required=True,
                        help="CSV: frame, tilt_x_deg, tilt_y_deg[, offset_mm]")
    lasers.add_argument("--line", type=Path, help="NPZ with line_x_px (frames x image rows)")
    lasers.add_argument("--fit-emitters", action="store_true",
                        help="also move each emitter onto its fitted beam")
    lasers.add_argument("--out", type=Path, required=True, help="rig file to write")
    _add_overwrite(lasers)
    lasers.set_defaults(run=_run_calibrate_lasers)
    rig = targets.add_parser(
        "rig", help="self-calibrate camera pose, beams and line plane from images of known "
                    "surfaces",
        description="Find every spot in each image without trusting the rig file's beams, "
                    "identify the diodes over the whole series (a beam through its emitter), "
                    "fit camera pose and beams jointly, then the line laser's plane through "
                    "the fitted camera; write the calibrated rig with uncertainties, a report "
                    "and one overlay per image.")
    rig.add_argument("--rig", type=Path, required=True, help="the rig file as designed")
    source = rig.add_mutually_exclusive_group(required=True)
    source.add_argument("--images", type=Path, nargs="+",
                        help="images of known surfaces (image k is frame k of --surfaces)")
    source.add_argument("--video", type=Path,
                        help="video of the tilt table: its still stretches (0.5 s or more), "
                             "in order, are the frames of --surfaces")
    rig.add_argument("--surfaces", type=Path, required=True,
                     help="CSV: frame, tilt_x_deg, tilt_y_deg[, offset_mm]")
    rig.add_argument("--out", type=Path, required=True, help="calibrated rig file to write")
    rig.add_argument("--cone-deg", type=float, default=3.0,
                     help="farthest a beam may lean from the rig file's direction [deg]")
    rig.add_argument("--camera-turn-deg", type=float, default=2.0,
                     help="farthest the camera may be turned from the rig file [deg]")
    rig.add_argument("--fit-emitters", action="store_true",
                     help="also fit each emitter's position across its beam")
    _add_overwrite(rig)
    rig.set_defaults(run=_run_calibrate_rig)
    plane = targets.add_parser(
        "line-plane", help="camera and line laser plane from a checkerboard crossed by the line",
        description="Calibrate the camera on the board, find the red line's centre per row "
                    "inside each board, put it on that board's plane and fit one plane to all "
                    "(camera frame, n.X + d = 0, mm); write it as JSON with its residuals.")
    plane.add_argument("--images", nargs="+", type=Path, required=True,
                       help="colour images, one board pose each, the line crossing the board")
    _add_board_arguments(plane)
    plane.add_argument("--model", choices=["pinhole", "scaramuzza"], default="pinhole")
    plane.add_argument("--out", type=Path, required=True, help="JSON file to write")
    _add_overwrite(plane)
    plane.set_defaults(run=_run_calibrate_line_plane)


def _run_calibrate_line_plane(args: argparse.Namespace) -> int:
    import json

    import numpy as np
    from sds_recon.calibration.board import Checkerboard

    from sds_bringup.line_plane_calibration import calibrate_line_plane, line_plane_report

    if _refused("calibrate line-plane", args.out, args.overwrite):
        return 2
    try:
        result = calibrate_line_plane(sorted(args.images),
                                      Checkerboard.parse(args.board, args.square), args.model)
        args.out.write_text(json.dumps(line_plane_report(result), indent=2) + "\n")
    except (OSError, ValueError) as error:
        print(f"sds calibrate line-plane: {error}", file=sys.stderr)
        return 2
    residuals = result.residuals_mm()
    normal = result.plane.normal
    print(f"line plane (camera frame): n = [{normal[0]:.6f}, {normal[1]:.6f}, {normal[2]:.6f}], "
          f"d = {-normal @ result.plane.point_mm:.3f} mm; {len(residuals)} points, "
          f"mean |residual| {np.mean(np.abs(residuals)):.3f} mm; camera RMS "
          f"{result.camera_run.calibration.rms_px:.3f} px")
    print(f"wrote {args.out}")
    return 0


def _run_calibrate_rig(args: argparse.Namespace) -> int:
    from sds_camera.frame_source import FrameSourceError
    from sds_recon.calibration.rig_calibration import CalibrationSettings
    from sds_recon.calibration.rig_report import report_text, rig_report
    from sds_recon.rig import load_rig

    from sds_bringup.rig_calibration import (
        calibrate_images,
        calibration_frames,
        known_surfaces,
        write_calibration,
    )

    if _refused("calibrate rig", args.out, args.overwrite):
        return 2
    try:
        rig = load_rig(args.rig)
        surfaces = known_surfaces(args.surfaces)
        images, names = calibration_frames(args.images or [args.video], rig, len(surfaces))
        settings = CalibrationSettings(cone_deg=args.cone_deg,
                                       camera_turn_deg=args.camera_turn_deg,
                                       fit_emitters=args.fit_emitters)
        result, found = calibrate_images(rig, images, surfaces, settings)
        write_calibration(rig, result, found, images, names, args.out,
                          f"`sds calibrate rig` from {args.rig}")
    except (OSError, ValueError, FrameSourceError) as error:  # RigError is a ValueError
        print(f"sds calibrate rig: {error}", file=sys.stderr)
        return 2
    print(report_text(rig_report(rig, result)))
    print(f"wrote {args.out} and its report, {args.out.with_suffix('')}.report.html")
    return 0


def _run_calibrate_lasers(args: argparse.Namespace) -> int:
    import json

    from sds_recon.calibration.laser_files import calibrate_lasers, report_text
    from sds_recon.rig import load_rig, save_rig

    if _refused("calibrate lasers", args.out, args.overwrite):
        return 2
    try:
        rig = load_rig(args.rig)
        calibrated, report = calibrate_lasers(rig, args.spots, args.surfaces, args.line,
                                              args.fit_emitters)
    except (OSError, ValueError) as error:  # RigError is a ValueError
        print(f"sds calibrate lasers: {error}", file=sys.stderr)
        return 2
    text = report_text(report)
    comment = f"Calibrated by `sds calibrate lasers` from {args.rig}:\n{text}"
    save_rig(calibrated, args.out, comment=comment)
    report_path = args.out.with_suffix(".report.json")
    report_path.write_text(json.dumps(report, indent=2) + "\n")
    print(text)
    print(f"wrote {args.out} and {report_path}")
    return 0


def _run_calibrate_camera(args: argparse.Namespace) -> int:
    from sds_recon.calibration.board import Checkerboard
    from sds_recon.calibration.camera_calibration import calibrate_camera
    from sds_recon.calibration.report import report_content, report_text, write_report
    from sds_recon.camera import save_camera

    if _refused("calibrate camera", args.out, args.overwrite):
        return 2
    try:
        board = Checkerboard.parse(args.board, args.square)
        run = calibrate_camera(sorted(args.images), board, args.model)
    except ValueError as error:
        print(f"sds calibrate camera: {error}", file=sys.stderr)
        return 2
    camera_path = save_camera(run.calibration.camera, args.out, comment=(
        f"Calibrated by `sds calibrate camera --model {args.model}` from "
        f"{len(run.calibration.views)} images of a {args.board} board, {args.square:g} mm squares: "
        f"RMS reprojection error {run.calibration.rms_px:.3f} px."))
    paths = write_report(run, camera_path.parent, camera_path.stem)
    print(report_text(report_content(run)))
    print(f"wrote {camera_path}, {paths['json']}, {paths['text']}, {paths['plot']}")
    return 0


IMPORTERS = {"ocamcalib": "read_ocamcalib_results", "matlab": "read_matlab_fisheye",
             "camera-info": "read_camera_info"}


def _add_camera(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser("camera", help="convert camera calibrations to and from SDS files")
    actions = parser.add_subparsers(title="actions", required=True, metavar="ACTION")
    importing = actions.add_parser(
        "import", help="write an SDS camera file from another tool's calibration",
        description="ocamcalib: OCamCalib's calib_results.txt; matlab: fisheyeIntrinsics "
                    "properties in YAML/JSON; camera-info: a ROS camera_info YAML (plumb_bob).")
    importing.add_argument("format", choices=sorted(IMPORTERS))
    importing.add_argument("source", type=Path)
    importing.add_argument("--out", type=Path, required=True, help="SDS camera file to write")
    _add_overwrite(importing)
    importing.set_defaults(run=_run_camera_import)
    exporting = actions.add_parser(
        "camera-info", help="write a ROS camera_info YAML from a pinhole SDS camera file")
    exporting.add_argument("camera", type=Path)
    exporting.add_argument("--out", type=Path, required=True)
    exporting.add_argument("--name", default="sds_camera", help="camera_name in the file")
    _add_overwrite(exporting)
    exporting.set_defaults(run=_run_camera_info)


def _run_camera_import(args: argparse.Namespace) -> int:
    from sds_recon.camera import CameraModelError, importers, save_camera

    if _refused("camera import", args.out, args.overwrite):
        return 2
    try:
        camera = getattr(importers, IMPORTERS[args.format])(args.source)
    except CameraModelError as error:
        print(f"sds camera import: {error}", file=sys.stderr)
        return 2
    save_camera(camera, args.out, comment=f"Imported from {args.format} file {args.source}.")
    print(f"wrote {args.out}: {camera}")
    return 0


def _run_camera_info(args: argparse.Namespace) -> int:
    from sds_recon.camera import CameraModelError, PinholeCamera, load_camera
    from sds_recon.camera.importers import write_camera_info

    if _refused("camera camera-info", args.out, args.overwrite):
        return 2
    try:
        camera = load_camera(args.camera)
    except CameraModelError as error:
        print(f"sds camera camera-info: {error}", file=sys.stderr)
        return 2
    if not isinstance(camera, PinholeCamera):
        print(f"sds camera camera-info: {args.camera} is a {camera.model_name} model; "
              "camera_info has no such model (keep the SDS file)", file=sys.stderr)
        return 2
    write_camera_info(camera, args.out, args.name)
    print(f"wrote {args.out}")
    return 0


def _add_simulate(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser(
        "simulate", help="render a simulated run: video, Arduino streams, ground truth",
        description="Render a scenario (config/scenarios/*.yaml) as the rig's camera and Arduino "
                    "would record it, with the exact truth beside it (format: sds_sim.simulate).")
    parser.add_argument("scenario", type=Path)
    parser.add_argument("--out", type=Path, default=Path("simulation"))
    parser.add_argument("--seconds", type=float, help="override the scenario's duration [s]")
    parser.add_argument("--scale", type=float, help="image scale, e.g. 0.25 for 960x540")
    parser.add_argument("--seed", type=int, help="override the scenario's random seed")
    parser.add_argument("--codec", choices=["h264", "lossless", "png"], default="h264")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace an earlier simulation in --out")
    parser.set_defaults(run=_run_simulate)


def _run_simulate(args: argparse.Namespace) -> int:
    import time

    from sds_sim.scenario import load_scenario
    from sds_sim.simulate import simulate

    overrides = {key: value for key, value in (("duration_s", args.seconds),
                                               ("scale", args.scale), ("seed", args.seed))
                 if value is not None}
    try:
        scenario = load_scenario(args.scenario, overrides)
    except ValueError as error:  # ScenarioError, RigError and CameraModelError included
        print(f"sds simulate: {error}", file=sys.stderr)
        return 2
    if _refused("simulate", args.out / "truth" / "run.json", args.overwrite,
                "exists: the folder holds a simulation already"):
        return 2
    start = time.perf_counter()
    output = simulate(scenario, args.out, codec=args.codec)
    seconds = time.perf_counter() - start
    print(f"{scenario.name}: {scenario.frame_count} frames "
          f"{output.run.parent.parent.name}/ in {seconds:.1f} s")
    for key in ("video", "serial", "sd_log", "run", "spots", "frames", "line"):
        print(f"  {key:<7} {getattr(output, key)}")
    return 0


def _add_resolution(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser(
        "resolution", help="ideal vertical resolution [mm/px] against laser radius (seed Fig. 7)",
        description="Camera looking straight down at a flat surface: how many mm of surface "
                    "height one pixel of spot motion means, for each radial spot position.",
    )
    parser.add_argument("--camera", type=Path,
                        default=CONFIG / "cameras" / "gopro_hero5_session.yaml")
    parser.add_argument("--height-mm", type=float, default=170.0,
                        help="camera above the flat surface [mm] (default 170)")
    parser.add_argument("--beam-tilt-deg", type=float, default=0.0,
                        help="beam tilt from the vertical, outwards [deg] (default 0)")
    parser.add_argument("--radii-mm", type=float, nargs=3, default=[0.0, 60.0, 1.0],
                        metavar=("START", "STOP", "STEP"), help="radii of the table [mm]")
    parser.add_argument("--rings-mm", type=float, nargs="*", default=[],
                        help="radii of the diode rings, drawn dashed")
    parser.add_argument("--out", type=Path, default=Path("resolution"),
                        help="directory for resolution.csv and resolution.png")
    parser.set_defaults(run=_run_resolution)


def _run_resolution(args: argparse.Namespace) -> int:
    import numpy as np
    from sds_recon.camera import CameraModelError, load_camera
    from sds_recon.resolution import plot_resolution, table_text, vertical_resolution

    try:
        camera = load_camera(args.camera)
    except CameraModelError as error:
        print(f"sds resolution: {error}", file=sys.stderr)
        return 2
    start, stop, step = args.radii_mm
    radii = np.arange(start, stop + step / 2, step)
    table = vertical_resolution(camera, radii, args.height_mm, np.radians(args.beam_tilt_deg))
    args.out.mkdir(parents=True, exist_ok=True)
    text = table_text(table)
    (args.out / "resolution.csv").write_text(text + "\n")
    plot_resolution(table, args.out / "resolution.png", args.rings_mm)
    print(text)
    print(f"wrote {args.out / 'resolution.csv'} and {args.out / 'resolution.png'}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of `sds` with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="sds",
        description="Sloshing Detection Subsystem: laser-based free-surface measurement.",
    )
    parser.add_argument("--version", action="version",
                        version=f"sds {importlib.metadata.version('sds_bringup')}")
    commands = parser.add_subparsers(title="commands", required=True, metavar="COMMAND")
    _add_graph(commands)
    _add_demo(commands)
    _add_calibrate(commands)
    _add_camera(commands)
    _add_simulate(commands)
    _add_resolution(commands)
    analyze.add_parser(commands)
    recording.add_parser(commands)
    clock_link.add_parser(commands)
    offline.add_parsers(commands)
    return parser


def main(argv: list[str] | None = None) -> None:
    """Entry point of the `sds` command."""
    args = build_parser().parse_args(argv)
    raise SystemExit(args.run(args))
