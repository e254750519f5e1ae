"""Results written whole or not at all: a run writes into a temporary sibling (a folder or a
file), which replaces the target only once the run is complete.

An interrupted or failed run (Ctrl-C, a corrupt input, a full disk) leaves the target as it
was: the earlier run's results, or nothing; never a mix of two runs, never an empty table that
blocks the retry.
"""

from __future__ import annotations

import logging
import os
import shutil
import signal
from collections.abc import Collection, Iterator
from contextlib import contextmanager
from pathlib import Path

STAGING_PREFIX = ".sds-partial-"
"""A staging folder's name: this, the process id, the target's name (hidden in listings)."""
READY_PREFIX = ".sds-ready-"
"""A complete staging folder about to replace its target (the next run finishes the swap)."""
OLD_PREFIX = ".sds-old-"
"""A target moved aside by the swap (removed once the new one is in place)."""
HELD_SIGNALS = {signal.SIGINT, signal.SIGTERM}
"""Signals held off while the staged files move into place (a few renames)."""
_log = logging.getLogger(__name__)


def staging_path(target: Path, prefix: str = STAGING_PREFIX) -> Path:
    """The temporary sibling (folder or file) a run for `target` writes into (or, with
    another prefix, the swap's names for it)."""
    return target.parent / f"{prefix}{os.getpid()}-{target.name}"


@contextmanager
def staged_folder(target: Path, replaces: Collection[str]) -> Iterator[Path]:
    """A fresh, empty staging folder beside `target` to write a run's files into.

    When the block ends normally, the staging folder becomes `target` in one rename
    (`commit`): with the entries of `target` that the run did not write and that `replaces`
    does not name (other files in the folder) linked into it first, so that the folder holds
    one run; SIGINT and SIGTERM wait until that is done. When the block raises (an error,
    KeyboardInterrupt), the staging folder is removed and `target` is untouched. Leftovers of
    killed runs beside `target` are dealt with first (`recover`)."""
    recover(target.parent)
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
    """Make the complete `staging` folder `target` (see `staged_folder`), signals held off:
    the kept entries are hard-linked into it, it is renamed "ready", the old target is moved
    aside, the ready folder renamed into place and the old one removed. A kill at any point
    leaves either the old or the new folder whole, and `recover` completes the swap."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, HELD_SIGNALS)
    try:
        if not target.exists():
            staging.rename(target)
            return
        written = {entry.name for entry in staging.iterdir()}
        for entry in target.iterdir():
            if entry.name not in written and entry.name not in replaces:
                _link(entry, staging / entry.name)
        ready, old = staging_path(target, READY_PREFIX), staging_path(target, OLD_PREFIX)
        staging.rename(ready)
        try:
            target.rename(old)
        except OSError:   # a folder that cannot move (the working folder, a mount point)
            _move_entries(ready, target)
            return
        ready.rename(target)
        _remove(old)
    finally:   # a signal that came meanwhile is delivered now
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


def _link(source: Path, destination: Path) -> None:
    """`source` (a file or a folder tree) at `destination` too, by hard links where the file
    system has them (no copy of a large recording), else copied."""
    if source.is_dir() and not source.is_symlink():
        shutil.copytree(source, destination, symlinks=True, copy_function=_link_file)
    else:
        _link_file(source, destination)


def _link_file(source: str | Path, destination: str | Path) -> None:
    if Path(source).is_symlink():
        os.symlink(os.readlink(source), destination)
        return
    try:
        os.link(source, destination)
    except OSError:
        shutil.copy2(source, destination)


def _move_entries(ready: Path, target: Path) -> None:
    """The fallback of a target that cannot be renamed: every entry of `ready` replaces its
    namesake in `target` (the folder's own entries that `ready` lacks are removed)."""
    names = {entry.name for entry in ready.iterdir()}
    for entry in target.iterdir():
        if entry.name not in names and not entry.name.startswith(
                (STAGING_PREFIX, READY_PREFIX, OLD_PREFIX)):
            _remove(entry)
    for entry in ready.iterdir():
        destination = target / entry.name
        if entry.is_dir() and destination.exists():
            _remove(destination)
        os.replace(entry, destination)
    ready.rmdir()


def recover(folder: Path) -> list[str]:
    """Finish or undo the swaps of runs that died in `folder` and remove their staging
    entries; what was done, one line each (also logged as warnings). An entry belongs to a
    dead run when no process has its process id."""
    done: list[str] = []
    if not folder.is_dir():
        return done
    leftovers = [(entry, *_owner(entry.name)) for entry in folder.iterdir()]
    dead = [(entry, prefix, name) for entry, prefix, pid, name in leftovers
            if prefix and not _alive(pid)]
    for entry, prefix, name in sorted(dead, key=lambda item: item[1] != READY_PREFIX):
        target = folder / name
        if prefix == READY_PREFIX and not target.exists():
            entry.rename(target)
            done.append(f"{target}: completed the commit of a run that was killed during it")
        elif prefix == OLD_PREFIX and not target.exists():
            entry.rename(target)
            done.append(f"{target}: restored, a run was killed while replacing it")
        else:
            _remove(entry)
            done.append(f"{entry}: removed, the unfinished output of a run that died")
    for line in done:
        _log.warning(line)
    return done


def _owner(name: str) -> tuple[str, int, str]:
    """(prefix, process id, target's name) of a staging entry's name; ('', 0, '') for
    anything else."""
    for prefix in (STAGING_PREFIX, READY_PREFIX, OLD_PREFIX):
        pid, dash, target = name.removeprefix(prefix).partition("-")
        if name.startswith(prefix) and dash and pid.isdigit():
            return prefix, int(pid), target
    return "", 0, ""


def _alive(pid: int) -> bool:
    """Whether a process with this id runs (this one does: its other stagings are in use)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:   # another user's process
        return True
    return True


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
    target.parent.mkdir(parents=True, exist_ok=True)
    recover(target.parent)
    staging = staging_path(target)
    try:
        yield staging
    except BaseException:
        _remove(staging)
        raise
    os.replace(staging, target)
