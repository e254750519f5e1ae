"""`sds mcap-repair`: a recording left without its summary (a crash) made whole again."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sds_record.mcap_files import repair


def add_parser(commands: argparse._SubParsersAction) -> None:
    """Register `sds mcap-repair`."""
    parser = commands.add_parser(
        "mcap-repair", help="rewrite an MCAP left without its summary (e.g. after a crash)",
        description="Copy every complete message of an MCAP file (one whose recorder was killed "
                    "keeps all flushed chunks) into a new file with a summary section.")
    parser.add_argument("source", type=Path)
    parser.add_argument("target", type=Path)
    parser.set_defaults(run=run)


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
