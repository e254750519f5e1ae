"""The `sds` subcommands, one module each.

Each module's `add_parser(commands)` registers its arguments and its `run(args) -> int`; `run`
imports what it needs when it runs, so that `sds --help` loads no numerical library. Bad input
ends a command with `CommandError` (or the error a reader raises: `OSError`, `ValueError`...):
`sds` prints it once, as "sds COMMAND: cause", and exits with code 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

COMMANDS = ("graph", "demo", "run", "calibrate", "camera", "simulate", "resolution", "process",
            "export", "analyze", "view", "mcap_repair", "import_sd", "import_gopro",
            "clock_link")
"""The command modules, in the order `sds --help` lists them."""


class CommandError(Exception):
    """Bad input to a command: one line on stderr, exit code 2."""


def refuse_existing(path: Path, overwrite: bool, what: str = "exists") -> None:
    """Raise CommandError when `path` exists and `--overwrite` was not given."""
    if path.exists() and not overwrite:
        raise CommandError(f"{path} {what} (another --out, or --overwrite)")


def add_overwrite(parser: argparse.ArgumentParser, text: str = "replace an existing --out"
                  ) -> None:
    """The `--overwrite` flag: without it no command replaces a file."""
    parser.add_argument("--overwrite", action="store_true", help=text)
