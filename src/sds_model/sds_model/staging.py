"""Results written whole or not at all: a run writes into a temporary sibling (a folder or a
file), which replaces the target only once the run is complete.

An interrupted or failed run (Ctrl-C, a corrupt input, a full disk) leaves the target as it
was: the earlier run's results, or nothing; never a mix of two runs, never an empty table that
blocks the retry.
"""

from __future__ import annotations

import os
import shutil
import signal
from collections.abc import Collection, Iterator
from contextlib import contextmanager
from pathlib import Path

STAGING_PREFIX = ".sds-partial-"
"""A staging folder's name: this, the process id, the target's name (hidden in listings)."""
HELD_SIGNALS = {signal.SIGINT, signal.SIGTERM}
"""Signals held off while the staged files move into place (a few renames)."""


def staging_path(target: Path) -> Path:
    """The temporary sibling (folder or file) a run for `target` writes into."""
    return target.parent / f"{STAGING_PREFIX}{os.getpid()}-{target.name}"


@contextmanager
def staged_folder(target: Path, replaces: Collection[str]) -> Iterator[Path]:
    """A fresh, empty staging folder beside `target` to write a run's files into.

    When the block ends normally, every entry of the staging folder replaces the same-named
    entry of `target` (created if absent), and the entries named in `replaces` that this run
    did not write (an earlier run's table or figure) are removed, so that the folder holds one
    run; other files in `target` are kept. SIGINT and SIGTERM wait until the renames are done.
    When the block raises (an error, KeyboardInterrupt), the staging folder is removed and
    `target` is untouched."""
    staging = staging_path(target)
    if staging.exists():
        shutil.rmtree(staging)
    staging.mkdir(parents=True)
    try:
        yield staging
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    commit(staging, target, replaces)


def commit(staging: Path, target: Path, replaces: Collection[str]) -> None:
    """Move the staged entries into `target` (see `staged_folder`), signals held off."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, HELD_SIGNALS)
    try:
        if not target.exists():
            staging.rename(target)
            return
        written = {entry.name for entry in staging.iterdir()}
        for name in set(replaces) - written:
            _remove(target / name)
        for entry in staging.iterdir():
            destination = target / entry.name
            if entry.is_dir() and destination.exists():
                _remove(destination)
            os.replace(entry, destination)
        staging.rmdir()
    finally:   # a signal that came meanwhile is delivered now
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


def _remove(path: Path) -> None:
    """A file or folder, if it exists."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()


@contextmanager
def staged_file(target: Path) -> Iterator[Path]:
    """A temporary sibling path to write `target`'s new content to: it replaces `target` (one
    atomic rename) when the block ends normally, and is removed when the block raises."""
    staging = staging_path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    try:
        yield staging
    except BaseException:
        _remove(staging)
        raise
    os.replace(staging, target)
