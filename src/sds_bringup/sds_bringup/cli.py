"""The `sds` command: one entry point, one subcommand per module of `sds_bringup.commands`."""

from __future__ import annotations

import argparse
import importlib
import importlib.metadata
import logging
import os
import sys

from sds_bringup.commands import COMMANDS, CommandError

# FFmpeg and OpenCV print their own lines for a corrupt video; the commands say it in one.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of `sds` with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="sds",
        description="Sloshing Detection Subsystem: laser-based free-surface measurement.",
    )
    parser.add_argument("--version", action="version",
                        version=f"sds {importlib.metadata.version('sds_bringup')}")
    commands = parser.add_subparsers(title="commands", required=True, metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"sds_bringup.commands.{name}").add_parser(commands)
    return parser


def input_errors() -> tuple[type[BaseException], ...]:
    """What bad input raises (a missing or corrupt file, a wrong rig or camera field, an
    unreadable video or recording); imported once such an error has happened."""
    from mcap.exceptions import McapError
    from sds_camera.frame_source import FrameSourceError

    return CommandError, OSError, ValueError, LookupError, FrameSourceError, McapError


def main(argv: list[str] | None = None) -> None:
    """Entry point of the `sds` command: bad input is one line and exit code 2."""
    # The libraries' warnings (e.g. an unfinished recording read up to its last chunk).
    logging.basicConfig(format="sds: %(message)s", level=logging.WARNING)
    try:
        args = build_parser().parse_args(argv)
        code = args.run(args)
    except KeyboardInterrupt:   # Ctrl-C outside a graph (a graph stops on its own signal)
        print("sds: interrupted", file=sys.stderr)
        code = 130
    except Exception as error:
        if not isinstance(error, input_errors()):
            raise
        print(f"sds {args.command}: {error}", file=sys.stderr)
        code = 2
    raise SystemExit(code)
