"""Running the dataflow in tests: the simulation node in-process under MockNode, and the
real dataflow.yml under `dora run` (a copy with absolute paths and extra nodes).
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import pyarrow as pa

from so101.dataflow import dataflow_copy, write_dataflow
from so101.venv import BIN as VENV_BIN, env_with_bin_first

ROOT = Path(__file__).resolve().parents[1]
RECORDER = ROOT / "tests" / "nodes" / "state_recorder.py"

# The simulation node's input as dataflow.yml declares it, and one tick of that timer.
TIMER_4MS = {"inputs": {"tick": {"source": "dora/timer/millis/4", "queue_size": 1}}}
TICK = ("tick", pa.array([], type=pa.null()))


def run_simulation_node(monkeypatch, events, node_config=TIMER_4MS, **env):
    """Run nodes/simulation_node.py's main() headless over `events`; returns (exit code, the MockNode)."""
    from dora.testing import MockNode

    import nodes.simulation_node as simulation_node

    monkeypatch.setenv("SO101_MODE", "direct")
    monkeypatch.setenv("SO101_LANG", "en")
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    node = MockNode(events, node_config=node_config)
    monkeypatch.setattr(simulation_node, "Node", lambda: node)
    return simulation_node.main(), node


def dora_env(**extra: str) -> dict[str, str]:
    """The environment for dora: this interpreter's bin first on PATH (dora starts nodes with that python)."""
    env = env_with_bin_first()
    env.pop("DISPLAY", None)
    env.update(extra)
    return env


def write_test_dataflow(tmp_path: Path, sim_env: dict[str, str] | None = None, record_file: Path | None = None) -> Path:
    """dataflow.yml with absolute node paths, the simulation forced headless, and optionally a recorder node."""
    descriptor = dataflow_copy({"SO101_MODE": "direct", **(sim_env or {})})
    if record_file is not None:
        descriptor["nodes"].append(
            {
                "id": "recorder",
                "path": str(RECORDER),
                "inputs": {"joint_state": "simulation/joint_state"},
                "env": {"RECORD_FILE": str(record_file)},
            }
        )
    return write_dataflow(descriptor, tmp_path / "dataflow.yml")


class DoraRun:
    """`dora run` in the background, its log in a file; stopped with Ctrl-C (SIGINT) like a person would."""

    def __init__(self, dataflow: Path, log_path: Path, stop_after_s: float = 60, **env: str):
        self.log_path = log_path
        self._log = log_path.open("wb")
        self.process = subprocess.Popen(
            [str(VENV_BIN / "dora"), "run", str(dataflow), "--stop-after", f"{stop_after_s:g}s"],
            cwd=dataflow.parent, stdout=self._log, stderr=subprocess.STDOUT, env=dora_env(**env),
            start_new_session=True,
        )

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")

    def wait_for(self, text: str, timeout_s: float = 30) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if text in self.log():
                return
            if self.process.poll() is not None:
                raise AssertionError(f"dora run exited ({self.process.returncode}) before {text!r}:\n{self.log()[-3000:]}")
            time.sleep(0.1)
        raise AssertionError(f"{text!r} not seen in {timeout_s}s:\n{self.log()[-3000:]}")

    def stop(self, timeout_s: float = 20) -> int:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                os.killpg(self.process.pid, signal.SIGKILL)
                self.process.wait()
        self._log.close()
        return self.process.returncode
