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


# -- dora dataflows on this machine ----------------------------------------------------------
# dora 1.1's `dora run` always listens for dynamic nodes (the prompt) on the daemon's default local
# port (53291), whatever DORA_DAEMON_LOCAL_LISTEN_PORT or --local-listen-port say; a second one finds
# the port taken, warns, and runs a dataflow no prompt can reach, while a prompt joins the first.

# dora's warning when that port is taken (dora_daemon::local_listener), as its log carries it.
DAEMON_PORT_TAKEN_MARK = "Daemon listen port already in use"


def command_line(pid: int) -> list[str]:
    """The arguments `pid` runs with ([] if gone or not ours)."""
    try:
        raw = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return []
    return [arg.decode(errors="replace") for arg in raw.split(b"\0") if arg]


def _program_arguments(args: list[str], program: str) -> list[str] | None:
    """What follows `program` in a command line (a pip-installed `dora` or `so101` is a Python script:
    `python .../dora run ...`), or None if it runs another program."""
    for index, arg in enumerate(args[:2]):
        if os.path.basename(arg) == program:
            return args[index + 1:]
    return None


def dora_run_dataflow(pid: int) -> Path | None:
    """The dataflow file a `dora run FILE` process runs, or None if `pid` is not one."""
    args = _program_arguments(command_line(pid), "dora")
    if not args or args[0] != "run":
        return None
    files = [arg for arg in args[1:] if not arg.startswith("-")]
    if not files:
        return None
    try:
        return Path(os.readlink(f"/proc/{pid}/cwd")) / files[0]
    except OSError:
        return None


def on_our_network(pid: int) -> bool:
    """Whether `pid` shares this process's network namespace, whose ports it could hold (a
    container's or another namespace's `dora run` cannot take ours); True where that cannot be read."""
    try:
        return os.readlink(f"/proc/{pid}/ns/net") == os.readlink("/proc/self/ns/net")
    except OSError:
        return True


def dora_runs() -> list[int]:
    """The pids of the `dora run` processes of this machine that are ours and share our network, in pid order."""
    pids = [int(entry.name) for entry in Path("/proc").iterdir() if entry.name.isdigit()]
    return sorted(pid for pid in pids if dora_run_dataflow(pid) is not None and alive(pid) and on_our_network(pid))


def who_runs(pid: int) -> str:
    """A dora process as a person knows it: the `so101` command that started it if one did, else its
    own command line and folder; with the pid to stop it by."""
    with contextlib.suppress(OSError, IndexError, ValueError):
        parent = int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
        so101_args = _program_arguments(command_line(parent), "so101")
        if so101_args is not None:
            return f"`so101 {' '.join(so101_args)}` (pid {parent})"
    dora_args = _program_arguments(command_line(pid), "dora")
    command = " ".join(["dora", *dora_args]) if dora_args is not None else " ".join(command_line(pid))
    try:
        folder = f" in {os.readlink(f'/proc/{pid}/cwd')}"
    except OSError:
        folder = ""
    return f"`{command}`{folder} (pid {pid})"
