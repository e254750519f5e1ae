"""`sds import-gopro`: a GoPro video's own IMU (GPMF telemetry) as an MCAP recording."""

from __future__ import annotations

import argparse

from sds_cli.commands import (
    CommandError,
    add_overwrite,
    existing_file,
    non_negative_float,
    output_file,
    refuse_existing,
)


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds import-gopro`."""
    parser = commands.add_parser(
        "import-gopro", help="a GoPro video's own IMU (GPMF telemetry) as an MCAP recording",
        description="Read the accelerometer and gyroscope of the video's GPMF track (GoPro's "
                    "parser) and write them as /camera/imu sensor_msgs/Imu messages (one "
                    "sensor per message, optical frame, SI units), stamped with the video's "
                    "clock plus --start-s; samples that would be stamped before 0 are left "
                    "out.")
    parser.add_argument("video", type=existing_file, help="a GoPro video (its GPMF IMU stream)")
    parser.add_argument("--out", type=output_file, help="MCAP to write (default: beside the video)")
    parser.add_argument("--start-s", type=non_negative_float, default=0.0,
                        help="time of the video's first frame on the recording's clock [s]")
    add_overwrite(parser)
    parser.set_defaults(run=run, command="import-gopro")


def run(args: argparse.Namespace) -> int:
    """Import and count the samples written."""
    from sds_camera.camera_imu import read_gopro_imu
    from sds_workflows.camera_imu_mcap import write_imu_mcap

    output = args.out or args.video.with_suffix(".imu.mcap")
    refuse_existing(output, args.overwrite)   # before the video is read
    imu = read_gopro_imu(args.video)
    if imu is None:
        raise CommandError(f"{args.video}: no GPMF telemetry track (not a GoPro video?)")
    written = write_imu_mcap(imu, output, round(args.start_s * 1e9), args.overwrite)
    total = len(imu.accel_time_s) + len(imu.gyro_time_s)
    left_out = total - written
    print(f"sds import-gopro: {written} of {total} samples ({len(imu.accel_time_s)} "
          f"accelerometer, {len(imu.gyro_time_s)} gyroscope) to {output} as /camera/imu"
          + (f"; {left_out} samples from before the first frame left out (they would be "
             f"stamped before 0 s: a larger --start-s keeps them)" if left_out else ""))
    return 0
