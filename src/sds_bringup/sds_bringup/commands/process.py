"""`sds process`: the graph's tracker, reconstruction and analysis in one process, no graph."""

from __future__ import annotations

import argparse
from pathlib import Path

from sds_bringup.commands import CommandError, add_overwrite


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds process`."""
    parser = commands.add_parser(
        "process", help="track, reconstruct and analyse a video or recording, no ROS graph",
        description="Run the graph's tracker, reconstruction and analysis in one process (the "
                    "parameters of config/graphs/drop.yaml) and write the result files.")
    inputs = parser.add_mutually_exclusive_group(required=True)
    inputs.add_argument("--video", type=Path, help="video file, or image folder (with --fps)")
    inputs.add_argument("--mcap", type=Path, help="recording with camera frames")
    parser.add_argument("--rig", type=Path,
                        help="the rig file (needed with --video; with --mcap, default: the one "
                             "the recording carries)")
    parser.add_argument("--out", type=Path, required=True,
                        help="folder for the result files (refused if it holds results)")
    add_overwrite(parser, "replace the results of an earlier run in --out")
    parser.add_argument("--fps", type=float, default=0.0,
                        help="frame rate of an image folder [1/s]")
    parser.add_argument("--gravity", type=float, help="gravity for the theory [m/s²]")
    parser.add_argument("--calibrate-lasers", type=Path, nargs="+", metavar="IMAGE",
                        help="images of known surfaces, or one video of the tilt table (its "
                             "still stretches in order): self-calibrate the rig first (needs "
                             "--surfaces) and process with the calibrated rig")
    parser.add_argument("--surfaces", type=Path,
                        help="known surface per image: frame, tilt_x_deg, tilt_y_deg"
                             "[, offset_mm] (frame k = k-th image)")
    parser.add_argument("--no-progress", action="store_true")
    parser.set_defaults(run=run, command="process")


def run(args: argparse.Namespace) -> int:
    """Result files and the analysis report of one video or recording."""
    from sds_camera.camera_imu import read_camera_imu
    from sds_recon.results import ResultsWriter
    from sds_recon.rig import load_rig
    from sds_recon.sloshing.analysis import AnalysisOptions
    from sds_recon.sloshing.gravity import gravity_regime
    from sds_record.recorded_series import read_accelerations, recording_rig

    from sds_bringup.offline import (
        RunTables,
        calibrate_from_images,
        finish_analysis,
        mcap_frames,
        process_frames,
        video_frames,
    )

    source = args.video or args.mcap
    if not source.exists():
        raise CommandError(f"{source}: no such file")
    if args.video and args.rig is None:
        raise CommandError("--video needs --rig (the rig the video was taken with)")
    rig = load_rig(args.rig) if args.video else recording_rig(source, args.rig)
    writer = ResultsWriter(args.out, args.overwrite)
    if args.calibrate_lasers:
        if args.surfaces is None:
            raise CommandError("--calibrate-lasers needs --surfaces")
        rig, rig_path = calibrate_from_images(rig, args.calibrate_lasers, args.surfaces,
                                              args.out)
        print(f"sds process: calibrated rig written to {rig_path}")
    frames = video_frames(source, rig, args.fps) if args.video else mcap_frames(source)
    tables = RunTables(writer, rig)
    count = process_frames(frames, rig, tables, progress=not args.no_progress)
    imu = read_camera_imu(source) if args.video else None
    accelerometers = read_accelerations(source) if args.mcap else {}
    if imu is not None:
        tables.add_camera_imu(imu)
        accelerometers["camera IMU"] = (imu.accel_time_s, imu.accel_m_s2)
    gravity, regime = args.gravity, ""
    if gravity is None:
        gravity, regime = gravity_regime(accelerometers)
    note = finish_analysis(tables, str(source), args.out, AnalysisOptions(gravity_m_s2=gravity))
    notes = "; ".join(n for n in (regime, note) if n)
    print(f"sds process: {count} frames of {source} -> {args.out}" + (f" ({notes})" if notes
                                                                       else ""))
    return 0
