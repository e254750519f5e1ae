"""`sds camera import|camera-info|readout`: camera calibrations to and from SDS camera files,
and the rolling shutter's readout measured."""

from __future__ import annotations

import argparse

from sds_cli.commands import (
    CommandError,
    add_overwrite,
    existing_file,
    output_file,
    positive_float,
    refuse_existing,
)

IMPORTERS = {"ocamcalib": "read_ocamcalib_results", "matlab": "read_matlab_fisheye",
             "camera-info": "read_camera_info"}
"""Format name → reader in sds_model.camera.importers."""


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds camera` and its actions."""
    parser = commands.add_parser("camera", help="convert camera calibrations to and from SDS "
                                                "files; measure the rolling shutter's readout")
    actions = parser.add_subparsers(title="actions", required=True, metavar="ACTION")
    importing = actions.add_parser(
        "import", help="write an SDS camera file from another tool's calibration",
        description="ocamcalib: OCamCalib's calib_results.txt; matlab: fisheyeIntrinsics "
                    "properties in YAML/JSON; camera-info: a ROS camera_info YAML (plumb_bob).")
    importing.add_argument("format", choices=sorted(IMPORTERS),
                           help="the other tool's file format")
    importing.add_argument("source", type=existing_file,
                           help="the other tool's calibration file")
    importing.add_argument("--out", type=output_file, required=True,
                           help="SDS camera file to write")
    add_overwrite(importing)
    importing.set_defaults(run=run_import, command="camera import")
    exporting = actions.add_parser(
        "camera-info", help="write a ROS camera_info YAML from a pinhole SDS camera file")
    exporting.add_argument("camera", type=existing_file, help="SDS camera file (pinhole)")
    exporting.add_argument("--out", type=output_file, required=True,
                           help="camera_info YAML to write")
    exporting.add_argument("--name", default="sds_camera", help="camera_name in the file")
    add_overwrite(exporting)
    exporting.set_defaults(run=run_camera_info, command="camera camera-info")
    readout = actions.add_parser(
        "readout", help="the rolling shutter's readout time from a video of a flickering light",
        description="Film a lamp on AC mains (100 Hz in 50 Hz countries, 120 Hz in 60 Hz ones) "
                    "or an LED blinking at a known rate, lighting a plain scene, a second or "
                    "more, with a short exposure (under the flicker period) and at a frame rate "
                    "that the flicker is not a multiple of (120 Hz at 30 fps stands still). The "
                    "bands' slope gives the time the camera takes to read its rows: the "
                    "camera file's readout_s.")
    readout.add_argument("video", type=existing_file, help="the flicker clip, at the camera's own "
                                                  "resolution and mode")
    readout.add_argument("--flicker-hz", type=positive_float, required=True,
                         help="the light's flicker frequency [Hz] (twice the mains frequency)")
    readout.add_argument("--camera", type=existing_file,
                         help="camera file: compare with the readout_s it states")
    readout.set_defaults(run=run_readout, command="camera readout")


def run_import(args: argparse.Namespace) -> int:
    """Another tool's calibration as an SDS camera file."""
    from sds_model.camera import importers, save_camera

    refuse_existing(args.out, args.overwrite)
    camera = getattr(importers, IMPORTERS[args.format])(args.source)
    save_camera(camera, args.out, comment=f"Imported from {args.format} file {args.source}.")
    print(f"wrote {args.out}: {camera}")
    return 0


def run_camera_info(args: argparse.Namespace) -> int:
    """A pinhole SDS camera file as a ROS camera_info YAML."""
    from sds_model.camera import PinholeCamera, load_camera
    from sds_model.camera.importers import write_camera_info

    refuse_existing(args.out, args.overwrite)
    camera = load_camera(args.camera)
    if not isinstance(camera, PinholeCamera):
        raise CommandError(f"{args.camera} is a {camera.model_name} model; camera_info has no "
                           "such model (keep the SDS file)")
    write_camera_info(camera, args.out, args.name)
    print(f"wrote {args.out}")
    return 0


def run_readout(args: argparse.Namespace) -> int:
    """The readout measured, with its σ, as the camera file's line."""
    from sds_camera.readout import video_readout
    from sds_model.camera.files import read_yaml
    from sds_model.camera.rolling_shutter import rolling_shutter

    stated = rolling_shutter(read_yaml(args.camera)) if args.camera else None
    estimate = video_readout(args.video, args.flicker_hz)
    print(f"sds camera readout: {args.video}: {estimate.readout_s * 1e3:.3f} ms ± "
          f"{estimate.sigma_s * 1e3:.3f} ms (bands' contrast {estimate.contrast:.2f}, "
          f"{estimate.frames} frames)")
    print(f"  for the camera file: readout_s: {estimate.readout_s:.5f}   (the direction is not "
          "measured: readout_direction, top_to_bottom by default)")
    if stated is not None:
        difference_ms = (estimate.readout_s - stated.readout_s) * 1e3
        print(f"  {args.camera} states readout_s: {stated.readout_s:g} "
              f"({difference_ms:+.3f} ms from the measurement)")
    return 0
