"""`sds import-sd`: an Arduino SD-card log as an MCAP recording."""

from __future__ import annotations

import argparse

from sds_cli.commands import (
    add_overwrite,
    existing_file,
    non_negative_float,
    output_file,
    refuse_existing,
)


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds import-sd`."""
    parser = commands.add_parser(
        "import-sd", help="an Arduino SD-card log as an MCAP recording",
        description="Turn the Arduino's SD-card log (protocol v1) into /arduino/imu, "
                    "/arduino/tof and /arduino/events messages in an MCAP file, stamped with "
                    "the device clock (seconds since the first record, plus --start-s).")
    parser.add_argument("log", type=existing_file, help="the Arduino's SD-card log (protocol v1)")
    parser.add_argument("--out", type=output_file, help="MCAP to write (default: beside the log)")
    parser.add_argument("--start-s", type=non_negative_float, default=0.0,
                        help="time of the log's first record on the recording's clock [s]")
    add_overwrite(parser)
    parser.set_defaults(run=run, command="import-sd")


def run(args: argparse.Namespace) -> int:
    """Import and count records, rejected lines and gaps."""
    from sds_record.import_sd import import_sd

    output = args.out or args.log.with_suffix(".mcap")
    refuse_existing(output, args.overwrite)   # before the log is read
    result = import_sd(args.log, output, start_s=args.start_s, overwrite=args.overwrite)
    print(f"sds import-sd: {result.records} records to {output} ({result.rejected_lines} "
          f"lines rejected, {result.missing_records} records missing by sequence number)")
    return 0
