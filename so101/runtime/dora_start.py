"""A dataflow started on a dora cluster with `dora start --attach`, watched as so101.runtime.dora_run.Dataflow
watches `dora run`: the attached CLI streams every node's log lines, from every machine, into one file
(each line says the node and its daemon), so the same ready lines and one-line refusals are found in it;
stopping it is `dora stop` for that dataflow, and the attached CLI ends with it. `so101 teleop
--coordinator` starts its dataflow this way (so101.launch.beside_prompt)."""

from __future__ import annotations

import re
import subprocess
import time
from pathlib import Path

from so101.runtime.cluster import Cluster
from so101.runtime.processes import stop_process
from so101.runtime.venv import dora_executable

STOP_TIMEOUT_S = 20.0
# The coordinator's line when a daemon could not start its nodes, as the attached CLI streams it.
SPAWN_FAILED = re.compile(r"spawn failed on daemon `(.+?)-[0-9a-f]{8}-[0-9a-f-]+`: (.*?)\s*$", re.MULTILINE)


class AttachedDataflow:
    """`dora start DATAFLOW --name NAME --attach` on `cluster`, its output (the nodes' logs) in `log`;
    `hints`: what to check, by node id, when a daemon cannot start that node."""

    def __init__(self, cluster: Cluster, dataflow: Path, name: str, log: Path,
                 ready_marks: tuple[tuple[str, ...], ...], hints: dict[str, str] | None = None):
        log.parent.mkdir(parents=True, exist_ok=True)
        self.cluster, self.name, self.log, self.ready_marks = cluster, name, log, ready_marks
        self.hints = hints or {}
        self._log_stream = log.open("wb")
        self.process = subprocess.Popen(
            [dora_executable() or "dora", "start", str(dataflow), "--name", name, "--attach"], cwd=dataflow.parent,
            stdin=subprocess.DEVNULL, stdout=self._log_stream, stderr=subprocess.STDOUT, env=cluster.env(),
            start_new_session=True,
        )

    def wait_ready(self, timeout_s: float) -> bool | None:
        """True once the log has a line of each of the ready marks; False if the dataflow ended first; None on timeout."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            log_text = self.log.read_text(encoding="utf-8", errors="replace")
            if all(any(mark in log_text for mark in marks) for marks in self.ready_marks):
                return True
            if self.process.poll() is not None:
                return False
            time.sleep(0.2)
        return None

    def failure(self) -> str | None:
        """Why a daemon could not start the dataflow's nodes, in one line (None: it did not say so)."""
        try:
            said = SPAWN_FAILED.search(self.log.read_text(encoding="utf-8", errors="replace"))
        except OSError:
            return None
        if said is None:
            return None
        machine, why = said.groups()
        hint = next((hint for node_id, hint in self.hints.items() if why.endswith(f"node {node_id}")), "")
        return f"dora could not start the dataflow on machine {machine!r}: {why}{f' ({hint})' if hint else ''}"

    def stop(self) -> None:
        """`dora stop` for this dataflow (every node, on every machine), then the attached CLI ends. Safe twice."""
        try:  # asked even when the CLI has ended: the dataflow may outlive it
            self.cluster.cli("stop", "--name", self.name, timeout_s=STOP_TIMEOUT_S)
            self.process.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            pass
        stop_process(self.process, STOP_TIMEOUT_S, ask_session=True)
        self._log_stream.close()
