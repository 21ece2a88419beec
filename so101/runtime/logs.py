"""Diagnostics go through `logging`, one logger per module (`logging.getLogger(__name__)`).

Every logger of the project is a child of "so101"; a program's entry point calls
`send_diagnostics_to()` once, and each record is written as its bare message, so a line reads
as a print would. A node sends them to stdout, which dora keeps in the node's log; a command
line tool or the prompt to stderr. Lines that tools parse (a body's "loaded" line, a CLI's
results) are not diagnostics: they are printed to stdout as they are.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path
from typing import Literal, TextIO

PROJECT_LOGGER = "so101"


class _CurrentStream(logging.StreamHandler):  # type: ignore[type-arg]
    """Writes to whatever sys.stdout or sys.stderr is at the time of each record (pytest swaps them)."""

    def __init__(self, stream_name: Literal["stdout", "stderr"]) -> None:
        super().__init__()
        self.stream_name = stream_name

    @property  # type: ignore[override]
    def stream(self) -> TextIO:
        return getattr(sys, self.stream_name)  # type: ignore[no-any-return]

    @stream.setter
    def stream(self, _value: TextIO) -> None:
        pass  # StreamHandler.__init__ sets it; the current one is looked up each time instead


def send_diagnostics_to(stream_name: Literal["stdout", "stderr"], level: int = logging.INFO) -> None:
    """The project's log records to stdout or stderr as bare messages; calling it again only moves them."""
    logger = logging.getLogger(PROJECT_LOGGER)
    handler = next((handler for handler in logger.handlers if isinstance(handler, _CurrentStream)), None)
    if handler is None:
        handler = _CurrentStream(stream_name)
        handler.setFormatter(logging.Formatter("%(message)s"))
        logger.addHandler(handler)
    handler.stream_name = stream_name
    logger.setLevel(level)
    logger.propagate = False


def keep_last_bytes(path: Path, max_bytes: int) -> None:
    """Cut the file at `path` down to its last `max_bytes` at most, from the start of a line, in place
    (a process appending to it meanwhile keeps appending): a log that every session appends to stays
    bounded. A smaller or missing file is left as it is."""
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        return
    if size <= max_bytes:
        return
    with path.open("r+b") as log_file:
        log_file.seek(size - max_bytes)
        tail = log_file.read(max_bytes)
        # The line cut in two is dropped whole (unless it is the only one).
        tail = tail[tail.find(b"\n") + 1:]
        log_file.seek(0)
        log_file.write(tail)
        log_file.truncate()
