"""`sds view`: a recording (MCAP) as a Rerun .rrd file."""

from __future__ import annotations

import argparse

from sds_cli.commands import (
    CommandError,
    add_overwrite,
    existing_file,
    output_file,
    positive_float,
    positive_int,
    refuse_existing,
)


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds view`."""
    parser = commands.add_parser(
        "view", help="a recording (MCAP) as a Rerun .rrd file",
        description="Log a recording's camera frames, spots, beam paths, line, surface points, "
                    "fitted plane, container and time series to a Rerun .rrd file (open it "
                    "with `rerun FILE.rrd`).")
    parser.add_argument("recording", type=existing_file, help="a recording (MCAP)")
    parser.add_argument("--out", type=output_file, help="the .rrd file (default: beside the MCAP)")
    parser.add_argument("--rig", type=existing_file,
                        help="rig file for the container, beams and beam paths (default: the "
                             "one the recording carries)")
    parser.add_argument("--image-scale", type=positive_float, default=0.25,
                        help="size of the logged images against the frames, in (0, 1] "
                             "(default 0.25)")
    parser.add_argument("--image-every", type=positive_int, default=1, help="log every Nth frame")
    add_overwrite(parser, "replace an existing .rrd file")
    parser.set_defaults(run=run, command="view")


def run(args: argparse.Namespace) -> int:
    """Convert and say how many messages the scene shows."""
    output = args.out or args.recording.with_suffix(".rrd")
    if not args.recording.is_file():
        raise CommandError(f"{args.recording}: no such recording")
    refuse_existing(output, args.overwrite)
    from sds_model.rig import load_rig
    from sds_record.recorded_series import recorded_rig
    from sds_viz.from_mcap import mcap_to_rrd

    rig = load_rig(args.rig) if args.rig else recorded_rig(args.recording)
    if rig is None:
        print(f"sds view: {args.recording} carries no rig and no --rig was given: the "
              "container, beams and beam paths are not drawn")
    conversion = mcap_to_rrd(args.recording, output, rig, args.image_scale, args.image_every)
    print(f"sds view: {conversion.shown} messages shown ({conversion.skipped} of types the "
          f"scene does not show) in {output}")
    return 0
