"""`dora run` started and watched for a command: in a session of its own, its log in a file.

Every command that runs a dataflow beside the terminal (so101 teleop, so101 replay: so101.launch)
starts it through `Dataflow`, waits for its nodes' ready lines, reads a node's one-line refusal out
of the log, and stops it leaving no process behind. A prompt joins a `dora run` through dora's one
port for dynamic nodes: `port_held_problem` says when another dataflow holds it.
"""

from __future__ import annotations

import re
import subprocess
import time
from pathlib import Path

from so101.runtime.processes import alive, descendants, kill_until_gone, stop_process, who_runs
from so101.runtime.venv import dora_executable
from so101.runtime.versions import DAEMON_DEFAULT_LOCAL_PORT, listening_process

STOP_TIMEOUT_S = 20.0
# How long a node may take to end after dora stopped, before it is killed (the real arm switches torque off).
NODE_GRACE_S = 5.0
LOG_TAIL_LINES = 15


def log_tail(log: Path) -> str:
    try:
        lines = log.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return ""
    return "\n".join("  " + line for line in lines[-LOG_TAIL_LINES:])


# A node's one line when it refuses to start (so101.runtime.node_events.cannot_start), or (the episodes'
# runner, the policy) to go on, as dora's log carries it.
REFUSAL = re.compile(r"(\[\w+\] cannot (?:start|go on): .*?)\s*$", re.MULTILINE)


def refusal(log: Path) -> str | None:
    """The first node's refusal to start in the dataflow's log, if one refused."""
    try:
        match = REFUSAL.search(log.read_text(encoding="utf-8", errors="replace"))
    except OSError:
        return None
    return match.group(1) if match else None


class Dataflow:
    """`dora run` in its own session (so the terminal's Ctrl-C reaches only the prompt), log to a file."""

    def __init__(self, dataflow: Path, log: Path, env: dict[str, str], ready_marks: tuple[tuple[str, ...], ...],
                 dora_args: list[str] | None = None):
        """`dora_args`: what the dora CLI is asked (default `run DATAFLOW`)."""
        log.parent.mkdir(parents=True, exist_ok=True)
        self.log = log
        self.ready_marks = ready_marks
        self._log_stream = log.open("wb")
        self.process = subprocess.Popen(
            [dora_executable() or "dora", *(dora_args or ["run", str(dataflow)])], cwd=dataflow.parent,
            stdin=subprocess.DEVNULL, stdout=self._log_stream, stderr=subprocess.STDOUT,
            env=env, start_new_session=True,
        )

    def wait_ready(self, timeout_s: float) -> bool | None:
        """True once the log has a line of each of the ready marks; False if dora exited first; None on timeout."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            log_text = self.log.read_text(encoding="utf-8", errors="replace")
            if all(any(mark in log_text for mark in marks) for marks in self.ready_marks):
                return True
            if self.process.poll() is not None:
                return False
            time.sleep(0.2)
        return None

    def stop(self) -> None:
        """Ctrl-C for dora (it stops every node), then SIGKILL for anything still alive."""
        nodes = descendants(self.process.pid)
        stop_process(self.process, STOP_TIMEOUT_S)
        kill_until_gone(lambda: [pid for pid in nodes if alive(pid)], timeout_s=5, grace_s=NODE_GRACE_S)
        self._log_stream.close()


def port_held_problem(template: str) -> str | None:
    """Why a dataflow started now would have its prompt join another one (`template`: TEXT's "port_held"),
    in one line; None if no dataflow holds dora's port."""
    holder = listening_process(DAEMON_DEFAULT_LOCAL_PORT)
    return template.format(port=DAEMON_DEFAULT_LOCAL_PORT, holder=who_runs(holder)) if holder else None
