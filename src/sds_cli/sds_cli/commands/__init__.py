"""The `sds` subcommands, one module each.

Each module's `add_parser(commands)` registers its arguments and its `run(args) -> int`; `run`
imports what it needs when it runs, so that `sds --help` loads no numerical library. Bad input
ends a command with an `InputError` (`CommandError` here, the readers' own subclasses): `sds`
prints it once, as "sds COMMAND: cause", and exits with code 2. The argument types below check
each option's value before any work starts (an argparse error: one line, exit code 2).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path
from typing import NoReturn

from sds_model.errors import InputError

COMMANDS = ("graph", "demo", "run", "calibrate", "camera", "simulate", "resolution", "process",
            "export", "analyze", "view", "mcap_repair", "import_sd", "import_gopro",
            "clock_link")
"""The command modules, in the order `sds --help` lists them."""


class CommandError(InputError):
    """Bad input to a command: one line on stderr, exit code 2."""


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose refusal is one line on stderr (not the usage and the error):
    "sds COMMAND: what is wrong (sds COMMAND --help)", exit code 2."""

    def error(self, message: str) -> NoReturn:
        print(f"{self.prog}: {message} ({self.prog} --help)", file=sys.stderr)
        raise SystemExit(2)


def positive_int(text: str) -> int:
    """An option's whole number of 1 or more."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text} must be 1 or more")
    return value


def _finite(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text} is not a finite number")
    return value


def positive_float(text: str) -> float:
    """An option's number above 0 (a rate, a duration, a scale)."""
    value = _finite(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"{text} must be above 0")
    return value


def non_negative_float(text: str) -> float:
    """An option's number of 0 or more (a gravity [m/s²]: 0 is weightlessness; a start)."""
    value = _finite(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text} must not be negative")
    return value


def existing_file(text: str) -> Path:
    """An input file that must exist (not a folder)."""
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a folder, not a file")
    if not path.is_file():
        raise argparse.ArgumentTypeError(f"{text}: no such file")
    if not os.access(path, os.R_OK):
        raise argparse.ArgumentTypeError(f"{text}: not readable (permissions)")
    return path


def existing_path(text: str) -> Path:
    """An input file or folder that must exist."""
    path = Path(text)
    if not path.exists():
        raise argparse.ArgumentTypeError(f"{text}: no such file or folder")
    return path


def existing_folder(text: str) -> Path:
    """An input folder that must exist."""
    path = Path(text)
    if not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: no such folder"
                                         + (" (it is a file)" if path.exists() else ""))
    return path


def output_folder(text: str) -> Path:
    """A folder to write into: it may not exist yet, but it must not be a file, and the
    nearest folder that exists must be writable."""
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a file, not a folder: name a folder")
    existing = next(p for p in (path, *path.absolute().parents) if p.exists())
    if not existing.is_dir() or not os.access(existing, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"{text}: {existing} is not a writable folder")
    return path


def output_file(text: str) -> Path:
    """A file to write: not a folder, in a folder that exists or can be made and is
    writable (whether it may be replaced is `refuse_existing`'s)."""
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a folder: name a file")
    existing = next(p for p in path.absolute().parents if p.exists())
    if not existing.is_dir() or not os.access(existing, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"{text}: {existing} is not a writable folder")
    return path


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
    side.add_argument("--lateral", type=existing_file, metavar="VIDEO",
                      help="the side camera's video")
    side.add_argument("--lateral-view", type=existing_file, metavar="FILE",
                      help="its view file (camera file, fps, LED region, board placements; "
                           "config/lateral/*.yaml)")
    side.add_argument("--lateral-board", type=existing_file, nargs="+", metavar="IMAGE",
                      help="its images of the checkerboard at the view file's placements "
                           "(one each, in order)")
    side.add_argument("--led-roi", type=int, nargs=4, metavar=("X", "Y", "W", "H"),
                      help="the sync LED's region in the top video (links the clocks)")
    side.add_argument("--arduino", type=existing_file, metavar="LOG",
                      help="the Arduino's log of the drop (SD card or serial capture): a "
                           "second clock link, through its LED record and acceleration")


def lateral_input(args: argparse.Namespace):
    """The side camera's inputs from `add_lateral_options`' arguments (None without
    --lateral); CommandError for what is missing."""
    if args.lateral is None:
        given = [flag for flag, value in (("--lateral-view", args.lateral_view),
                                          ("--lateral-board", args.lateral_board),
                                          ("--led-roi", args.led_roi),
                                          ("--arduino", args.arduino)) if value is not None]
        if given:   # they only link and place a side camera: alone they would do nothing
            raise CommandError(f"{' '.join(given)} go(es) with --lateral (the side camera's "
                               "video); an Arduino log alone: sds import-sd LOG")
        return None
    if args.lateral_view is None or args.lateral_board is None:
        raise CommandError("--lateral needs --lateral-view and --lateral-board")
    if args.led_roi is None and args.arduino is None:
        raise CommandError("--lateral needs --led-roi (the LED in the top video) or --arduino "
                           "(its log) to link the side camera's clock")
    from sds_workflows.lateral import LateralInput

    return LateralInput(args.lateral, args.lateral_view, tuple(args.lateral_board),
                        tuple(args.led_roi) if args.led_roi else None, args.arduino)
