"""Diagnostics go through `logging`, one logger per module (`logging.getLogger(__name__)`).

Every logger of the project is a child of "so101"; a program's entry point calls
`send_diagnostics_to_stderr()` once, and each record is written as its bare message, so a line
reads the same as a print would. Lines that tools parse (a body's "loaded" line, a CLI's
results) are not diagnostics: they stay on stdout as they are.
"""

from __future__ import annotations

import logging
import sys

PROJECT_LOGGER = "so101"


class _CurrentStderr(logging.StreamHandler):
    """Writes to whatever sys.stderr is at the time (pytest swaps it per test)."""

    def __init__(self) -> None:
        super().__init__()

    @property  # type: ignore[override]
    def stream(self):  # noqa: D401 - logging reads this attribute
        return sys.stderr

    @stream.setter
    def stream(self, _value) -> None:
        pass


def send_diagnostics_to_stderr(level: int = logging.INFO) -> None:
    """The project's log records to stderr as bare messages; calling it again changes nothing."""
    logger = logging.getLogger(PROJECT_LOGGER)
    if not any(isinstance(handler, _CurrentStderr) for handler in logger.handlers):
        handler = _CurrentStderr()
        handler.setFormatter(logging.Formatter("%(message)s"))
        logger.addHandler(handler)
    logger.setLevel(level)
    logger.propagate = False
