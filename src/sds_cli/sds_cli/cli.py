"""The `sds` command: one entry point, one subcommand per module of `sds_cli.commands`."""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import time
import traceback
from pathlib import Path

from sds_model.errors import InputError

from sds_cli.commands import COMMANDS, OneLineParser

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
    parser = OneLineParser(
        prog="sds",
        description="Sloshing Detection Subsystem: laser-based free-surface measurement.",
    )
    parser.add_argument("--version", action=VersionAction,
                        help="show the program's version number and exit")
    commands = parser.add_subparsers(title="commands", required=True, metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"sds_cli.commands.{name}").add_parser(commands)
    return parser


class CtrlC:
    """Python's own Ctrl-C (a KeyboardInterrupt), remembered: compiled code that catches the
    KeyboardInterrupt may raise another error in its place (matplotlib's Agg renderer, a
    figure being drawn: `ValueError: Invalid bounding box`, no cause attached)."""

    def __init__(self) -> None:
        self.pressed = False

    def __call__(self, signum: int, frame: object) -> None:
        self.pressed = True
        raise KeyboardInterrupt


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


def crash_log(error: BaseException, argv: list[str]) -> Path:
    """Write the traceback of a fault of the program to a new file under the user's state
    folder ($XDG_STATE_HOME/sds, default ~/.local/state/sds); its path."""
    state = Path(os.environ.get("XDG_STATE_HOME") or Path.home() / ".local" / "state")
    folder = state / "sds"
    folder.mkdir(parents=True, exist_ok=True)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    path = folder / f"crash-{stamp}-{os.getpid()}.log"
    path.write_text(f"sds {' '.join(argv)}\n\n"
                    + "".join(traceback.format_exception(error)))
    return path


def fault(command: str, error: BaseException, argv: list[str]) -> int:
    """Report a fault of the program (not of the input) in one line that points to its
    traceback; exit code 1."""
    try:
        where = f"the traceback is in {crash_log(error, argv)}"
    except OSError:   # no state folder: the traceback goes to the console instead
        traceback.print_exception(error)
        where = "the traceback is above"
    print(f"sds {command}: internal error ({type(error).__name__}: {error}); {where}; "
          "please report it", file=sys.stderr)
    return 1


def main(argv: list[str] | None = None) -> None:
    """Entry point of the `sds` command: bad input (`InputError`) is one line and exit code
    2, a fault of the program one line, its traceback in a log file and exit code 1; once
    the command is done, its process ignores Ctrl-C."""
    command = "command"
    ctrl_c = CtrlC()
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:   # not ignored
        signal.signal(signal.SIGINT, ctrl_c)
    try:
        args = build_parser().parse_args(argv)
        command = args.command
        # The libraries' warnings (e.g. an unfinished recording read up to its last chunk);
        # imported here so that `sds --help` does not pay for logging.
        import logging
        logging.basicConfig(format="sds: %(message)s", level=logging.WARNING)
        code = args.run(args)
    except KeyboardInterrupt:   # Ctrl-C outside a graph (a graph stops on its own signal)
        code = interrupted()
    except InputError as error:
        print(f"sds {command}: {error}", file=sys.stderr)
        code = 2
    except Exception as error:
        code = interrupted() if ctrl_c.pressed or _is_interruption(error) else \
            fault(command, error, sys.argv[1:] if argv is None else argv)
    finally:
        # Done, or refused: a Ctrl-C from now on has nothing to stop. Python exits with
        # threads, pools and compiled code still closing, part of it with SIGINT's default
        # action, so a late Ctrl-C killed the process (signal 2) instead of this exit code.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    raise SystemExit(code)
