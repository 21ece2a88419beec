"""One machine, several pytest-xdist workers: a test that must run alone holds this lock exclusively,
every other test holds it shared (tests/conftest.py).

flock favours no one: a worker that drops its shared hold and takes it again at once could keep a
waiting exclusive taker out for ever. So a taker first passes a turnstile (a second lock): the
exclusive taker holds it while it waits, and shared takers queue behind it."""

from __future__ import annotations

import fcntl
from pathlib import Path


class MachineLock:
    def __init__(self, folder: Path):
        self._turnstile = open(folder / "turnstile.lock", "a")
        self._machine = open(folder / "machine.lock", "a")
        self.held: str | None = None  # "exclusive", "shared" or None

    def take(self, exclusive: bool) -> None:
        wanted = "exclusive" if exclusive else "shared"
        if self.held == wanted:
            return
        self.release()
        fcntl.flock(self._turnstile, fcntl.LOCK_EX)
        try:
            if not exclusive:  # through the turnstile at once: only a waiting exclusive taker holds it long
                fcntl.flock(self._turnstile, fcntl.LOCK_UN)
            fcntl.flock(self._machine, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
        finally:
            fcntl.flock(self._turnstile, fcntl.LOCK_UN)
        self.held = wanted

    def release(self) -> None:
        if self.held is not None:
            fcntl.flock(self._machine, fcntl.LOCK_UN)
            self.held = None
