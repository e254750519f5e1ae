"""`sds camera import|camera-info`: camera calibrations to and from SDS camera files."""

from __future__ import annotations

import argparse
from pathlib import Path

from sds_cli.commands import CommandError, add_overwrite, refuse_existing

IMPORTERS = {"ocamcalib": "read_ocamcalib_results", "matlab": "read_matlab_fisheye",
             "camera-info": "read_camera_info"}
"""Format name → reader in sds_model.camera.importers."""


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds camera` and its actions."""
    parser = commands.add_parser("camera", help="convert camera calibrations to and from SDS files")
    actions = parser.add_subparsers(title="actions", required=True, metavar="ACTION")
    importing = actions.add_parser(
        "import", help="write an SDS camera file from another tool's calibration",
        description="ocamcalib: OCamCalib's calib_results.txt; matlab: fisheyeIntrinsics "
                    "properties in YAML/JSON; camera-info: a ROS camera_info YAML (plumb_bob).")
    importing.add_argument("format", choices=sorted(IMPORTERS),
                           help="the other tool's file format")
    importing.add_argument("source", type=Path, help="the other tool's calibration file")
    importing.add_argument("--out", type=Path, required=True, help="SDS camera file to write")
    add_overwrite(importing)
    importing.set_defaults(run=run_import, command="camera import")
    exporting = actions.add_parser(
        "camera-info", help="write a ROS camera_info YAML from a pinhole SDS camera file")
    exporting.add_argument("camera", type=Path, help="SDS camera file (pinhole)")
    exporting.add_argument("--out", type=Path, required=True,
                           help="camera_info YAML to write")
    exporting.add_argument("--name", default="sds_camera", help="camera_name in the file")
    add_overwrite(exporting)
    exporting.set_defaults(run=run_camera_info, command="camera camera-info")


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
