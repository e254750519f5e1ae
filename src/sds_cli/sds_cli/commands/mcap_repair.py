"""`sds mcap-repair`: a recording left without its summary (a killed recorder), indexed again."""

from __future__ import annotations

import argparse

from sds_cli.commands import add_overwrite, existing_file, output_file


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds mcap-repair`."""
    parser = commands.add_parser(
        "mcap-repair", help="rewrite an MCAP left without its summary (e.g. after a crash)",
        description="Copy every complete message of an MCAP file (one whose recorder was killed "
                    "keeps all flushed chunks) into a new file with a summary section.")
    parser.add_argument("source", type=existing_file, help="the recording without a summary")
    parser.add_argument("target", type=output_file, help="the new, indexed recording to write")
    add_overwrite(parser, "replace an existing target")
    parser.set_defaults(run=run, command="mcap-repair")


def run(args: argparse.Namespace) -> int:
    """Repair and say how many messages were copied."""
    from sds_record.mcap_files import repair

    report = repair(args.source, args.target, overwrite=args.overwrite)
    state = "had a summary" if report.had_summary else "had no summary"
    print(f"sds mcap-repair: {args.source} ({state}): {report.messages} messages on "
          f"{report.topics} topics written to {args.target}")
    return 0
