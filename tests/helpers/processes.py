"""Processes a test started: lines read from one's output with a timeout, and the ones a test's
`dora run` started, found by the marker in their environment, until they are gone."""

from __future__ import annotations

import os
import select
import time
from pathlib import Path

from so101.runtime.processes import processes_with_env


class Lines:
    """Lines from a subprocess's stdout, with a timeout."""

    def __init__(self, stream):
        self.fd = stream.fileno()
        self.pending = b""

    def next(self, timeout: float = 10.0) -> str:
        deadline = time.monotonic() + timeout
        while b"\n" not in self.pending:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self.fd], [], [], left)[0]:
                raise TimeoutError(f"no line within {timeout} s; so far {self.pending!r}")
            chunk = os.read(self.fd, 4096)
            if not chunk:
                raise EOFError(f"output ended; so far {self.pending!r}")
            self.pending += chunk
        line, self.pending = self.pending.split(b"\n", 1)
        return line.decode()


def processes_with_marker(marker: str) -> list[int]:
    """PIDs whose environment holds SO101_TEST_RUN=marker: `dora run` and every node it started."""
    return processes_with_env("SO101_TEST_RUN", marker)


def command_line(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def wait_until_gone(marker: str, timeout_s: float = 15) -> list[int]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        left = processes_with_marker(marker)
        if not left:
            return []
        time.sleep(0.2)
    return processes_with_marker(marker)
