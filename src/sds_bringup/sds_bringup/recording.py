"""Recording files: `sds mcap-repair`, `sds view` and `sds import-sd`."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sds_arduino.import_sd import import_sd
from sds_recon.rig import RigError, load_rig
from sds_record.mcap_files import repair
from sds_viz.from_mcap import mcap_to_rrd

from sds_bringup.paths import CONFIG


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds mcap-repair` and `sds view`."""
    parser = commands.add_parser(
        "mcap-repair", help="rewrite an MCAP left without its summary (e.g. after a crash)",
        description="Copy every complete message of an MCAP file (one whose recorder was killed "
                    "keeps all flushed chunks) into a new file with a summary section.")
    parser.add_argument("source", type=Path)
    parser.add_argument("target", type=Path)
    parser.set_defaults(run=run)
    add_view_parser(commands)
    add_import_sd_parser(commands)


def run(args: argparse.Namespace) -> int:
    """Repair; a one-line error and exit code 2 on bad input."""
    try:
        report = repair(args.source, args.target)
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
    parser.set_defaults(run=run_import_sd)


def run_import_sd(args: argparse.Namespace) -> int:
    """Import; a one-line error and exit code 2 on bad input."""
    output = args.out or args.log.with_suffix(".mcap")
    try:
        result = import_sd(args.log, output, start_s=args.start_s)
    except (OSError, ValueError) as error:
        print(f"sds import-sd: {error}", file=sys.stderr)
        return 2
    print(f"sds import-sd: {result.records} records to {output} ({result.rejected_lines} "
          f"lines rejected, {result.missing_records} records missing by sequence number)")
    return 0
