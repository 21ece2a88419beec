"""Finding the processes a run started, by a marker in their environment: dora's daemons start
the nodes, so a node is not our child, but it inherits the environment it was given."""

from __future__ import annotations

import contextlib
import os
import signal
import time
from pathlib import Path


def processes_with_env(name: str, value: str) -> list[int]:
    """The pids of our processes whose environment holds name=value."""
    wanted = f"{name}={value}".encode()
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            with contextlib.suppress(OSError):  # gone meanwhile, or not ours
                if wanted in (entry / "environ").read_bytes().split(b"\0"):
                    found.append(int(entry.name))
    return found


def alive(pid: int) -> bool:
    """Whether `pid` still runs; a zombie (exited, not yet reaped by its dead parent) counts as gone."""
    try:
        os.kill(pid, 0)
    except OSError:
        return False
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return True


def running_with_env(name: str, value: str) -> list[int]:
    """Those of `processes_with_env` that still run."""
    return [pid for pid in processes_with_env(name, value) if alive(pid)]


def kill_with_env(name: str, value: str, timeout_s: float) -> None:
    """SIGKILL every process holding name=value (nodes outlive a daemon killed hard), until none
    runs or `timeout_s` is up: a killed process takes a moment to go."""
    deadline = time.monotonic() + timeout_s
    while (pids := running_with_env(name, value)) and time.monotonic() < deadline:
        for pid in pids:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        time.sleep(0.05)
