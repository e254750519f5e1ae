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


def add_lateral_options(parser: argparse.ArgumentParser, description: str) -> None:
    """The side camera's options (`sds process`, `sds run`): its video, view file, board
    images, and what links its clock (the top video's LED region, the Arduino's log)."""
    side = parser.add_argument_group("side camera", description)
    side.add_argument("--lateral", type=Path, metavar="VIDEO", help="the side camera's video")
    side.add_argument("--lateral-view", type=Path, metavar="FILE",
                      help="its view file (camera file, fps, LED region, board placements; "
                           "config/lateral/*.yaml)")
    side.add_argument("--lateral-board", type=Path, nargs="+", metavar="IMAGE",
                      help="its images of the checkerboard at the view file's placements "
                           "(one each, in order)")
    side.add_argument("--led-roi", type=int, nargs=4, metavar=("X", "Y", "W", "H"),
                      help="the sync LED's region in the top video (links the clocks)")
    side.add_argument("--arduino", type=Path, metavar="LOG",
                      help="the Arduino's log of the drop (SD card or serial capture): a "
                           "second clock link, through its LED record and acceleration")


def lateral_input(args: argparse.Namespace):
    """The side camera's inputs from `add_lateral_options`' arguments (None without
    --lateral); CommandError for what is missing."""
    if args.lateral is None:
        return None
    if args.lateral_view is None or args.lateral_board is None:
        raise CommandError("--lateral needs --lateral-view and --lateral-board")
    if args.led_roi is None and args.arduino is None:
        raise CommandError("--lateral needs --led-roi (the LED in the top video) or --arduino "
                           "(its log) to link the side camera's clock")
    from sds_workflows.lateral import LateralInput

    return LateralInput(args.lateral, args.lateral_view, tuple(args.lateral_board),
                        tuple(args.led_roi) if args.led_roi else None, args.arduino)
