"""The `sds` command: one entry point, one subcommand per module of `sds_cli.commands`."""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys

from sds_cli.commands import COMMANDS, CommandError

# FFmpeg and OpenCV print their own lines for a corrupt video; the commands say it in one.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")


class VersionAction(argparse.Action):
    """`--version`: the installed version, looked up only when asked (importing
    importlib.metadata would cost every `sds` call a quarter of its start-up)."""

    def __init__(self, option_strings: list[str], dest: str, help: str | None = None) -> None:
        super().__init__(option_strings, dest, nargs=0, help=help)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: object, option_string: str | None = None) -> None:
        import importlib.metadata

        print(f"sds {importlib.metadata.version('sds_cli')}")   # on stdout, as argparse's own
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of `sds` with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="sds",
        description="Sloshing Detection Subsystem: laser-based free-surface measurement.",
    )
    parser.add_argument("--version", action=VersionAction,
                        help="show the program's version number and exit")
    commands = parser.add_subparsers(title="commands", required=True, metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"sds_cli.commands.{name}").add_parser(commands)
    return parser


def input_errors() -> tuple[type[BaseException], ...]:
    """What bad input raises: a command's own CommandError and the workflows' input errors;
    imported once such an error has happened."""
    from sds_workflows.errors import input_errors as workflow_input_errors

    return CommandError, *workflow_input_errors()


def _is_interruption(error: BaseException | None) -> bool:
    """Ctrl-C inside compiled code: numba's functions surface it as a SystemError caused by
    the KeyboardInterrupt, or by another such SystemError (one per nested numba call)."""
    while isinstance(error, SystemError):
        error = error.__cause__ or error.__context__
    return isinstance(error, KeyboardInterrupt)


def interrupted() -> int:
    """Say so, and the exit code of an interruption (128 + SIGINT)."""
    print("sds: interrupted", file=sys.stderr)
    return 130


def main(argv: list[str] | None = None) -> None:
    """Entry point of the `sds` command: bad input is one line and exit code 2; once the
    command is done, its process ignores Ctrl-C."""
    try:
        args = build_parser().parse_args(argv)
        # The libraries' warnings (e.g. an unfinished recording read up to its last chunk);
        # imported here so that `sds --help` does not pay for logging.
        import logging
        logging.basicConfig(format="sds: %(message)s", level=logging.WARNING)
        code = args.run(args)
    except KeyboardInterrupt:   # Ctrl-C outside a graph (a graph stops on its own signal)
        code = interrupted()
    except Exception as error:
        if _is_interruption(error):
            code = interrupted()
        elif isinstance(error, input_errors()):
            print(f"sds {args.command}: {error}", file=sys.stderr)
            code = 2
        else:
            raise
    finally:
        # Done, or refused: a Ctrl-C from now on has nothing to stop. Python exits with
        # threads, pools and compiled code still closing, part of it with SIGINT's default
        # action, so a late Ctrl-C killed the process (signal 2) instead of this exit code.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    raise SystemExit(code)
