"""Stopping what a run started, in one way everywhere: a process is asked first (Ctrl-C), then
killed; what it spawned is found by a marker in the environment (dora's daemons start the nodes,
so a node is not our child, but it inherits the environment it was given) or as its descendants."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import time
from pathlib import Path
from typing import Callable, Iterable


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


def stop_process(process: subprocess.Popen, timeout_s: float, *, ask_session: bool = False,
                 kill_session: bool = False, first_signal: int = signal.SIGINT) -> int:
    """Ask `process` to stop (Ctrl-C unless `first_signal` says otherwise), give it `timeout_s`, then
    SIGKILL it; returns its exit code. For a process started with start_new_session:
    `ask_session` sends the first signal to its whole process group, as a terminal's Ctrl-C does;
    `kill_session` always ends with SIGKILL to the group, which also ends what the process spawned
    and left behind. Safe on a process already gone, and twice."""

    def send(signal_number: int, session: bool) -> None:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            if session:
                os.killpg(process.pid, signal_number)
            elif process.poll() is None:
                process.send_signal(signal_number)

    if process.poll() is None:
        send(first_signal, ask_session)
        with contextlib.suppress(subprocess.TimeoutExpired):
            process.wait(timeout_s)
    if kill_session or process.poll() is None:
        send(signal.SIGKILL, kill_session)
    return process.wait()


def kill_until_gone(running: Callable[[], Iterable[int]], timeout_s: float, grace_s: float = 0.0) -> None:
    """SIGKILL the pids `running()` lists, again and again until it lists none or `timeout_s` is up
    (a killed process takes a moment to go). With `grace_s`, first wait that long for them to end
    by themselves (a node that was sent STOP may still be switching a servo's torque off)."""
    grace_deadline = time.monotonic() + grace_s
    while running() and time.monotonic() < grace_deadline:
        time.sleep(0.1)
    deadline = time.monotonic() + timeout_s
    while (pids := list(running())) and time.monotonic() < deadline:
        for pid in pids:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        time.sleep(0.05)


def kill_with_env(name: str, value: str, timeout_s: float) -> None:
    """SIGKILL every process holding name=value (nodes outlive a daemon killed hard) until none runs."""
    kill_until_gone(lambda: running_with_env(name, value), timeout_s)


def descendants(pid: int) -> list[int]:
    """Every process below `pid` (Linux /proc; elsewhere an empty list)."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").glob("[0-9]*/stat"):
        try:
            # The command name may hold spaces and parentheses: the fields after the last ')' are safe.
            fields = entry.read_text().rsplit(")", 1)[1].split()
            children.setdefault(int(fields[1]), []).append(int(entry.parent.name))
        except (OSError, IndexError, ValueError):
            continue
    found, queue = [], [pid]
    while queue:
        for child in children.get(queue.pop(), []):
            found.append(child)
            queue.append(child)
    return found


def yield_cpu_to_the_body() -> None:
    """This process runs only on CPU time no other process wants (Linux's SCHED_IDLE), so it never
    delays a body's tick: the recorder and the camera. Elsewhere, the lowest niceness dora's
    nodes can take back from (`nice` 19)."""
    try:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):
        with contextlib.suppress(OSError):
            os.nice(19)
