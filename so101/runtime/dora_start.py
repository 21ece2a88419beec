"""A dataflow started on a dora cluster with `dora start --attach`, watched as so101.runtime.dora_run.Dataflow
watches `dora run`: the attached CLI streams every node's log lines, from every machine, into one file
(each line says the node and its daemon), so the same ready lines and one-line refusals are found in it;
stopping it is `dora stop` for that dataflow, and the attached CLI ends with it. `so101 teleop
--coordinator` starts its dataflow this way (so101.launch.beside_prompt)."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

from so101.runtime.cluster import Cluster
from so101.runtime.dora_run import STOP_TIMEOUT_S, Dataflow
from so101.runtime.processes import stop_process

# The coordinator's line when a daemon could not start its nodes, as the attached CLI streams it.
SPAWN_FAILED = re.compile(r"spawn failed on daemon `(.+?)-[0-9a-f]{8}-[0-9a-f-]+`: (.*?)\s*$", re.MULTILINE)


class AttachedDataflow(Dataflow):
    """`dora start DATAFLOW --name NAME --attach` on `cluster`, its output (the nodes' logs) in `log`;
    `hints`: what to check, by node id, when a daemon cannot start that node."""

    def __init__(self, cluster: Cluster, dataflow: Path, name: str, log: Path,
                 ready_marks: tuple[tuple[str, ...], ...], hints: dict[str, str] | None = None):
        super().__init__(dataflow, log, cluster.env(), ready_marks,
                         dora_args=["start", str(dataflow), "--name", name, "--attach"])
        self.cluster, self.name = cluster, name
        self.hints = hints or {}

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
