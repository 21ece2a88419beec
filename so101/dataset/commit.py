"""How a save becomes part of a dataset whole or not at all: the writer's lock, the commit's
journal, and the recovery whoever opens the dataset next does.

Nothing is lost: the episode being recorded lives in memory and its videos in DIR/.so101-work/.
A save (a Plan) changes files in three ways:

- a new or rewritten file (info.json, stats.json, tasks.parquet, meta/episodes, a new data
  file, a joined video) is written beside its final name (NAME.so101-new) and fsynced;
- a finished video is moved in from the work folder;
- the data file this writer session grows gets the episode's row group and a new footer in
  place (a Splice, see parquet_append.py), fsynced; the bytes it writes over (the old footer)
  are made durable first, in an undo record (meta/.so101-undo.json).

Then a journal (meta/.so101-commit.json) naming the renames is made durable: that is the
commit. Then the renames are done, and the undo record and the journal removed, in that order.
Opening the dataset (reader or writer) finishes the renames of a journal it finds; without a
journal, it writes back the old bytes an undo record holds; then it removes temporary and work
files. A save that fails before its journal undoes the same at once. A crash at any moment thus
leaves every saved episode readable, and the episode being saved either whole or absent, once
this project has opened the dataset: a reader of its own (LeRobot's) that comes first after a
crash may find a commit half renamed, or the data file half grown.

Readers hold meta/ with a shared lock while they read the metadata or a data file; the writer
takes it exclusively while it renames, or writes a file in place, so a reader never sees either
half done.
"""

from __future__ import annotations

import base64
import errno
import fcntl
import json
import os
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

from so101.dataset.layout import DatasetError, write_json
from so101.dataset.video import VideoWriteError

# This writer's own files, never LeRobot's: LeRobot globs `*/*.parquet` and reads the paths in
# the episode rows, so it passes over all of them.
WORK_DIR = ".so101-work"
JOURNAL_PATH = "meta/.so101-commit.json"
UNDO_PATH = "meta/.so101-undo.json"
TEMP_SUFFIX = ".so101-new"
# A reader that is recovering holds the dataset folder's lock for a moment: a writer waits this long.
LOCK_WAIT_S = 5.0


@dataclass(frozen=True)
class Splice:
    """A file changed in place: it keeps its first `keep_bytes` bytes, `tail` replaces the rest."""

    path: str  # relative to the dataset's folder
    keep_bytes: int
    tail: bytes


@dataclass
class Plan:
    """A commit's files: written beside their final names, moved in whole, changed in place."""

    writes: list[tuple[str, Callable[[Path], object]]] = field(default_factory=list)
    moves: list[tuple[Path, str]] = field(default_factory=list)
    splices: list[Splice] = field(default_factory=list)


class CommitIncomplete(DatasetError):
    """A save that left its journal or undo record behind: the next open completes or undoes it."""

    def __init__(self, message: str, reason: str):
        super().__init__(message)
        self.reason = reason


def one_line_os_error(error: OSError) -> str:
    where = f" ({error.filename})" if error.filename else ""
    return f"{error.strerror or error}{where}"


def not_saved(what: str, root: Path, reason: str) -> DatasetError:
    return DatasetError(f"{what} is not saved: {reason}; the dataset in {root} is as it was")


def fsync_path(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextmanager
def flock(path: Path, operation: int) -> Iterator[None]:
    fd = os.open(path, os.O_RDONLY)
    try:
        fcntl.flock(fd, operation)
        yield
    finally:
        os.close(fd)  # closing releases the lock


def try_lock(path: Path) -> int | None:
    """An exclusive lock on a folder, held until the returned descriptor is closed; None if held elsewhere."""
    fd = os.open(path, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as error:
        os.close(fd)
        if error.errno in (errno.EWOULDBLOCK, errno.EAGAIN):
            return None
        raise
    return fd


def lock_for_writing(root: Path) -> int:
    """The dataset folder's lock, for a writer's life (waiting out a recovering reader)."""
    deadline = time.monotonic() + LOCK_WAIT_S
    while True:
        fd = try_lock(root)
        if fd is not None:
            return fd
        if time.monotonic() > deadline:
            raise DatasetError(f"another recorder is writing to {root}: stop it first, or use another folder")
        time.sleep(0.05)


def is_ours(name: str) -> bool:
    return name == WORK_DIR or name.endswith(TEMP_SUFFIX)


def make_folders(folder: Path) -> list[Path]:
    """mkdir -p, returning the folders it made (outermost first)."""
    missing: list[Path] = []
    while not folder.exists():
        missing.append(folder)
        folder = folder.parent
    for path in reversed(missing):
        path.mkdir()
    return list(reversed(missing))


def place_durably(root: Path, name: str, data: object, temps: list[Path]) -> None:
    """A JSON file written whole under its name, durably (temp, fsync, rename, fsync its folder)."""
    temp = root / (name + TEMP_SUFFIX)
    temps.append(temp)
    write_json(temp, data)
    fsync_path(temp)
    os.replace(temp, root / name)
    fsync_path((root / name).parent)


def _splice(path: Path, keep_bytes: int, tail: bytes) -> None:
    with open(path, "r+b") as file:
        file.seek(keep_bytes)
        file.write(tail)
        file.truncate()


def _undo_splices(root: Path, undo: list[Splice]) -> None:
    """Put back the old tails (under the metadata lock: a reader never sees a file half written),
    make them durable, then drop the undo record."""
    with flock(root / "meta", fcntl.LOCK_EX):
        for splice in undo:
            if (root / splice.path).exists():
                _splice(root / splice.path, splice.keep_bytes, splice.tail)
    for splice in undo:
        if (root / splice.path).exists():
            fsync_path(root / splice.path)
    if (root / UNDO_PATH).exists():
        (root / UNDO_PATH).unlink()
        fsync_path(root / "meta")


def commit(root: Path, plan: Plan, what: str) -> None:
    """Make `plan` part of the dataset in `root` (see the module's doc); `what` names it in errors
    ("episode 3"). A failure before the journal leaves the dataset exactly as it was."""
    temps: list[Path] = []
    created: list[Path] = []
    renames: list[tuple[str, str]] = []
    undo: list[Splice] = []  # the old tails of the files changed so far
    journal = root / JOURNAL_PATH
    try:
        for final, write in plan.writes:
            final_path = root / final
            created += make_folders(final_path.parent)
            temp = final_path.with_name(final_path.name + TEMP_SUFFIX)
            temps.append(temp)
            write(temp)
            fsync_path(temp)
            renames.append((str(temp.relative_to(root)), final))
        for source, final in plan.moves:
            created += make_folders((root / final).parent)
            fsync_path(source)
            renames.append((str(source.relative_to(root)), final))
        for folder in {(root / name).parent for name, _ in renames} | {p.parent for p in created}:
            fsync_path(folder)
        if plan.splices:
            old_tails = []
            for splice in plan.splices:
                with open(root / splice.path, "rb") as file:
                    file.seek(splice.keep_bytes)
                    old_tails.append(Splice(splice.path, splice.keep_bytes, file.read()))
            place_durably(root, UNDO_PATH, {"splices": [[s.path, s.keep_bytes, base64.b64encode(s.tail).decode()]
                                                         for s in old_tails]}, temps)
            with flock(root / "meta", fcntl.LOCK_EX):
                for splice, old in zip(plan.splices, old_tails):
                    undo.append(old)  # before the first byte: a write cut short is undone too
                    _splice(root / splice.path, splice.keep_bytes, splice.tail)
            for splice in plan.splices:
                fsync_path(root / splice.path)
        place_durably(root, JOURNAL_PATH, {"renames": renames}, temps)
    except BaseException as error:
        # Not committed: remove every trace, the dataset stays exactly as it was. A journal that
        # made it into place goes durably first: found later, it would commit what is undone here.
        try:
            if journal.exists():
                journal.unlink()
                fsync_path(journal.parent)
            _undo_splices(root, undo)
        except OSError as cleanup_error:
            reason = one_line_os_error(cleanup_error)
            raise CommitIncomplete(f"{what} could not be saved nor {root} put back as it was ({reason}): it is one "
                                   f"or the other when {root} is next opened", reason) from None
        for temp in temps:
            temp.unlink(missing_ok=True)
        for folder in reversed(created):
            try:
                folder.rmdir()
            except OSError:
                pass
        if not isinstance(error, (OSError, VideoWriteError)):
            raise
        raise not_saved(what, root, one_line_os_error(error) if isinstance(error, OSError) else str(error)) from None
    try:
        with flock(root / "meta", fcntl.LOCK_EX):
            _roll_forward(root, renames)
    except OSError as error:
        # The journal is whole: the next open completes these renames.
        reason = one_line_os_error(error)
        raise CommitIncomplete(f"{what} is saved but not yet in place ({reason}): it is completed when {root} "
                               "is next opened", reason) from None


def _roll_forward(root: Path, renames: list[tuple[str, str]]) -> None:
    """Do the journal's renames that are not done yet (a temp that is gone was renamed), then
    drop the undo record (its splices are committed) before the journal."""
    folders: set[Path] = set()
    for source, target in renames:
        if (root / source).exists():
            os.replace(root / source, root / target)
            folders.update({(root / source).parent, (root / target).parent})
    for folder in folders:
        if folder.exists():
            fsync_path(folder)
    if (root / UNDO_PATH).exists():
        (root / UNDO_PATH).unlink()
        fsync_path(root / "meta")
    (root / JOURNAL_PATH).unlink(missing_ok=True)
    fsync_path(root / "meta")


def _read_record(path: Path, key: str) -> list[list[Any]]:
    try:
        return [list(entry) for entry in json.loads(path.read_text(encoding="utf-8"))[key]]
    except (ValueError, KeyError, TypeError):
        return []  # cannot happen (both are renamed into place whole); drop it


def recover(root: Path) -> None:
    """Complete an interrupted commit (its journal exists: every temp was written and fsynced),
    or undo its splices (an undo record without a journal), then remove what an interrupted
    commit or recording left (temps, work files).

    The caller holds the dataset folder's lock: no writer is alive."""
    journal = root / JOURNAL_PATH
    if journal.exists():
        renames = [(str(a), str(b)) for a, b in _read_record(journal, "renames")]
        with flock(root / "meta", fcntl.LOCK_EX):
            _roll_forward(root, renames)
    elif (root / UNDO_PATH).exists():
        _undo_splices(root, [Splice(str(path), int(keep), base64.b64decode(tail))
                             for path, keep, tail in _read_record(root / UNDO_PATH, "splices")])
    for folder in ("meta", "data", "videos"):
        if (root / folder).is_dir():
            for temp in (root / folder).rglob("*" + TEMP_SUFFIX):
                temp.unlink(missing_ok=True)
    work = root / WORK_DIR
    if work.is_dir():
        for stale in work.iterdir():
            stale.unlink(missing_ok=True)
        work.rmdir()


@contextmanager
def consistent_view(root: Path) -> Iterator[None]:
    """Recover if no writer is alive, then hold the metadata still (no commit renames or splices) while reading."""
    fd = try_lock(root)
    if fd is not None:
        try:
            recover(root)
        finally:
            os.close(fd)
    with flock(root / "meta", fcntl.LOCK_SH):
        yield
