"""Faults on a real `dora run`, headless: the simulation node killed mid-run.

dataflow.yml leaves the simulation under dora 1.1's default restart policy
(`never`): a killed simulation stops the whole dataflow with the node, the
signal and its stderr in the log, and `dora run` exits non-zero. A restart
would bring the arm back at home with its targets lost, reopen a GUI window the
person had just closed, and loop on a missing model file.
"""

from __future__ import annotations

import os
import re
import signal
import time
import uuid
from pathlib import Path

import pytest

from tests.dataflow_helpers import DoraRun, write_test_dataflow

pytestmark = pytest.mark.dataflow

ANSI_ESCAPE = re.compile(r"\x1b\[[0-9;]*m")


def plain(text: str) -> str:
    return ANSI_ESCAPE.sub("", text)


def processes_with_marker(marker: str) -> list[int]:
    """PIDs whose environment holds SO101_TEST_RUN=marker: `dora run` and every node it started."""
    needle = f"SO101_TEST_RUN={marker}".encode()
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if needle in (entry / "environ").read_bytes().split(b"\0"):
                    found.append(int(entry.name))
            except OSError:  # gone meanwhile, or not ours
                pass
    return found


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


def test_killed_simulation_stops_the_dataflow_with_a_clear_report(tmp_path):
    marker = uuid.uuid4().hex
    record_file = tmp_path / "joint_state.json"
    dataflow = write_test_dataflow(tmp_path, sim_env={"SO101_LANG": "en"}, record_file=record_file)
    dora = DoraRun(dataflow, tmp_path / "dora.log", stop_after_s=120, SO101_TEST_RUN=marker)
    try:
        dora.wait_for("SO-101 loaded", timeout_s=60)
        simulation = [pid for pid in processes_with_marker(marker) if "simulation_node.py" in command_line(pid)]
        assert len(simulation) == 1, [command_line(pid) for pid in processes_with_marker(marker)]
        os.kill(simulation[0], signal.SIGKILL)
        # Under the `never` policy `dora run` ends by itself, long before --stop-after.
        exit_code = dora.process.wait(60)
    finally:
        dora.stop()
        left = wait_until_gone(marker)
    log = plain(dora.log())

    assert exit_code == 1
    # The line a person sees as it happens, and the summary `dora run` ends with.
    assert "ERROR  simulation: daemon exited because of signal SIGKILL" in log, log[-3000:]
    assert "Node `simulation` failed: exited because of signal SIGKILL" in log
    assert "restarting node" not in log
    # The other nodes stopped cleanly: the recorder finished and wrote what it had received.
    assert "recorder finished successfully" in log
    assert record_file.exists()
    assert left == [], [command_line(pid) for pid in left]
