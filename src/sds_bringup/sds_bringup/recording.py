"""Recording files: `sds mcap-repair`, `sds view`, `sds import-sd` and `sds import-gopro`."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rclpy.serialization import serialize_message
from sds_arduino.import_sd import import_sd
from sds_camera.camera_imu import CameraImu, read_gopro_imu
from sds_camera.imu_msg import imu_messages
from sds_recon.rig import RigError, load_rig
from sds_record.mcap_files import McapRecorder, repair
from sds_viz.from_mcap import mcap_to_rrd

from sds_bringup.offline import CAMERA_IMU_TOPIC
from sds_bringup.paths import CONFIG


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds mcap-repair` and `sds view`."""
    parser = commands.add_parser(
        "mcap-repair", help="rewrite an MCAP left without its summary (e.g. after a crash)",
        description="Copy every complete message of an MCAP file (one whose recorder was killed "
                    "keeps all flushed chunks) into a new file with a summary section.")
    parser.add_argument("source", type=Path, help="the recording without a summary")
    parser.add_argument("target", type=Path, help="the new, indexed recording to write")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing target")
    parser.set_defaults(run=run)
    add_view_parser(commands)
    add_import_sd_parser(commands)
    add_import_gopro_parser(commands)


def run(args: argparse.Namespace) -> int:
    """Repair; a one-line error and exit code 2 on bad input."""
    try:
        report = repair(args.source, args.target, overwrite=args.overwrite)
    except (OSError, ValueError) as error:
        print(f"sds mcap-repair: {error}", file=sys.stderr)
        return 2
    state = "had a summary" if report.had_summary else "had no summary"
    print(f"sds mcap-repair: {args.source} ({state}): {report.messages} messages on "
          f"{report.topics} topics written to {args.target}")
    return 0


def add_view_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds view`."""
    parser = commands.add_parser(
        "view", help="a recording (MCAP) as a Rerun .rrd file",
        description="Log a recording's camera frames, spots, beam paths, line, surface points, "
                    "fitted plane, container and time series to a Rerun .rrd file (open it "
                    "with `rerun FILE.rrd`).")
    parser.add_argument("recording", type=Path)
    parser.add_argument("--out", type=Path, help="the .rrd file (default: beside the MCAP)")
    parser.add_argument("--rig", type=Path, default=CONFIG / "rigs" / "stelium.yaml",
                        help="rig file for the container, beams and beam paths")
    parser.add_argument("--image-scale", type=float, default=0.25)
    parser.add_argument("--image-every", type=int, default=1, help="log every Nth frame")
    parser.set_defaults(run=run_view)


def run_view(args: argparse.Namespace) -> int:
    """Convert; a one-line error and exit code 2 on bad input."""
    output = args.out or args.recording.with_suffix(".rrd")
    try:
        if not args.recording.is_file():
            raise ValueError(f"{args.recording}: no such recording")
        conversion = mcap_to_rrd(args.recording, output, load_rig(args.rig), args.image_scale,
                                 args.image_every)
    except (OSError, ValueError, RigError) as error:
        print(f"sds view: {error}", file=sys.stderr)
        return 2
    print(f"sds view: {conversion.shown} messages shown ({conversion.skipped} of types the "
          f"scene does not show) in {output}")
    return 0


def add_import_sd_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds import-sd`."""
    parser = commands.add_parser(
        "import-sd", help="an Arduino SD-card log as an MCAP recording",
        description="Turn the Arduino's SD-card log (protocol v1) into /arduino/imu, "
                    "/arduino/tof and /arduino/events messages in an MCAP file, stamped with "
                    "the device clock (seconds since the first record, plus --start-s).")
    parser.add_argument("log", type=Path)
    parser.add_argument("--out", type=Path, help="MCAP to write (default: beside the log)")
    parser.add_argument("--start-s", type=float, default=0.0,
                        help="time of the log's first record on the recording's clock [s]")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    parser.set_defaults(run=run_import_sd)


def run_import_sd(args: argparse.Namespace) -> int:
    """Import; a one-line error and exit code 2 on bad input."""
    output = args.out or args.log.with_suffix(".mcap")
    try:
        result = import_sd(args.log, output, start_s=args.start_s, overwrite=args.overwrite)
    except (OSError, ValueError) as error:
        print(f"sds import-sd: {error}", file=sys.stderr)
        return 2
    print(f"sds import-sd: {result.records} records to {output} ({result.rejected_lines} "
          f"lines rejected, {result.missing_records} records missing by sequence number)")
    return 0


def add_import_gopro_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds import-gopro`."""
    parser = commands.add_parser(
        "import-gopro", help="a GoPro video's own IMU (GPMF telemetry) as an MCAP recording",
        description="Read the accelerometer and gyroscope of the video's GPMF track (GoPro's "
                    "parser) and write them as /camera/imu sensor_msgs/Imu messages (one "
                    "sensor per message, optical frame, SI units), stamped with the video's "
                    "clock plus --start-s; samples that would be stamped before 0 are left "
                    "out.")
    parser.add_argument("video", type=Path)
    parser.add_argument("--out", type=Path, help="MCAP to write (default: beside the video)")
    parser.add_argument("--start-s", type=float, default=0.0,
                        help="time of the video's first frame on the recording's clock [s]")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    parser.set_defaults(run=run_import_gopro)


def run_import_gopro(args: argparse.Namespace) -> int:
    """Import; a one-line error and exit code 2 on bad input."""
    output = args.out or args.video.with_suffix(".imu.mcap")
    try:
        imu = read_gopro_imu(args.video)
        if imu is None:
            raise ValueError(f"{args.video}: no GPMF telemetry track (not a GoPro video?)")
        written = write_imu_mcap(imu, output, round(args.start_s * 1e9), args.overwrite)
    except (OSError, ValueError) as error:
        print(f"sds import-gopro: {error}", file=sys.stderr)
        return 2
    total = len(imu.accel_time_s) + len(imu.gyro_time_s)
    print(f"sds import-gopro: {written} of {total} samples ({len(imu.accel_time_s)} "
          f"accelerometer, {len(imu.gyro_time_s)} gyroscope) to {output} as /camera/imu")
    return 0


def write_imu_mcap(imu: CameraImu, output: Path, origin_ns: int, overwrite: bool = False,
                   frame_id: str = "camera_optical") -> int:
    """The camera IMU's samples as /camera/imu messages in a new MCAP; how many."""
    recorder = McapRecorder(output, overwrite=overwrite)
    count = 0
    try:
        recorder.add_topic(CAMERA_IMU_TOPIC, "sensor_msgs/msg/Imu")
        for stamp_ns, msg in imu_messages(imu, origin_ns, frame_id):
            recorder.write(CAMERA_IMU_TOPIC, serialize_message(msg), stamp_ns, stamp_ns)
            count += 1
    finally:
        recorder.close()
    return count
