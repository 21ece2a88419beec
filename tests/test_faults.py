"""Faults on a real `dora run`, headless: the prompt or the simulation node killed mid-run.

dataflow.yml leaves the simulation under dora 1.1's default restart policy
(`never`): a killed simulation stops the whole dataflow with the node, the
signal and its stderr in the log, and `dora run` exits non-zero. A restart
would bring the arm back at home with its targets lost, reopen a GUI window the
person had just closed, and loop on a missing model file.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
import uuid

import pytest
import yaml

from so101.bodies.registry import BODIES
from so101.runtime.dataflow import timer_period_s
from tests.helpers.dataflow import PROMPT_COMMAND, DoraRun, body_environment, dora_env, prompt_env, write_test_dataflow
from tests.helpers.processes import command_line, processes_with_marker, wait_until_gone

pytestmark = pytest.mark.dataflow

ANSI_ESCAPE = re.compile(r"\x1b\[[0-9;]*m")


def plain(text: str) -> str:
    return ANSI_ESCAPE.sub("", text)


@pytest.mark.parametrize("body", list(BODIES))
def test_killed_simulation_stops_the_dataflow_with_a_clear_report(tmp_path, body):
    marker = uuid.uuid4().hex
    record_file = tmp_path / "joint_state.json"
    node_id = BODIES[body].node_id
    with body_environment(body, tmp_path) as (body_env, _):
        dataflow = write_test_dataflow(tmp_path, sim_env={"SO101_LANG": "en", **body_env}, record_file=record_file, body=body)
        dora = DoraRun(dataflow, tmp_path / "dora.log", stop_after_s=120, SO101_TEST_RUN=marker)
        try:
            dora.wait_for("SO-101 loaded", timeout_s=60)
            node_file = BODIES[body].node_file.name
            simulation = [pid for pid in processes_with_marker(marker) if node_file in command_line(pid)]
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
    assert f"ERROR  {node_id}: daemon exited because of signal SIGKILL" in log, log[-3000:]
    assert f"Node `{node_id}` failed: exited because of signal SIGKILL" in log
    assert "restarting node" not in log
    # The other nodes stopped cleanly: the recorder finished and wrote what it had received.
    assert "recorder finished successfully" in log
    assert record_file.exists()
    assert left == [], [command_line(pid) for pid in left]


@pytest.mark.parametrize("body", list(BODIES))
def test_killed_prompt_leaves_the_simulation_running_and_a_new_prompt_drives_it(tmp_path, body):
    with body_environment(body, tmp_path) as (body_env, _):
        killed_prompt_leaves_the_body_running(tmp_path, body, body_env)


def killed_prompt_leaves_the_body_running(tmp_path, body: str, body_env: dict[str, str]) -> None:
    record_file = tmp_path / "joint_state.json"
    dataflow = write_test_dataflow(tmp_path, sim_env={"SO101_LANG": "en", **body_env}, record_file=record_file, body=body)
    dora = DoraRun(dataflow, tmp_path / "dora.log", stop_after_s=120)
    try:
        dora.wait_for("SO-101 loaded", timeout_s=60)
        first = subprocess.Popen(
            PROMPT_COMMAND, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            text=True, env=prompt_env(tmp_path),
        )
        first.stdin.write("0 45\n")
        first.stdin.flush()  # stdin stays open: the prompt waits for more, as at a keyboard
        dora.wait_for("joint 0 target -> 45°", timeout_s=30)
        time.sleep(1.0)  # 45° at 3 rad/s takes 0.26 s in PyBullet; MuJoCo's servo settles in about 0.6 s
        first.kill()
        first.wait(10)
        killed_at = time.monotonic()
        time.sleep(1.0)
        second = subprocess.run(
            PROMPT_COMMAND, input="0 -45\n", capture_output=True, text=True, env=prompt_env(tmp_path), timeout=60,
        )
        dora.wait_for("joint 0 target -> -45°", timeout_s=30)
        time.sleep(1.5)
    finally:
        exit_code = dora.stop()
    log = plain(dora.log())

    assert second.returncode == 0, second.stdout + second.stderr
    assert "  → joint 0 (shoulder_pan) → -45°" in second.stdout, second.stdout
    assert exit_code == 0, log[-3000:]
    samples = json.loads(record_file.read_text())["samples"]
    # While no prompt is connected the body keeps publishing at its tick's rate (250 Hz for the
    # simulations, 50 Hz for the real arm), holding the first prompt's target.
    rate_hz = 1.0 / timer_period_s(next(node for node in yaml.safe_load(dataflow.read_text())["nodes"]
                                        if node["id"] == BODIES[body].node_id))
    alone = [state for t, state in samples if killed_at < t < killed_at + 1.0]
    assert len(alone) >= 0.8 * rate_hz, len(alone)
    assert all(abs(state[0] - 45.0) <= 1.0 for state in alone), alone[-1]
    # The new prompt's command reached the arm.
    assert abs(samples[-1][1][0] - (-45.0)) <= 1.0, samples[-1]
    assert "Traceback" not in log


# Joins as the prompt and sends a burst of commands, faster than the simulation logs them.
BURST_SENDER = """
import sys
import pyarrow as pa
from dora import Node

node = Node("keyboard_control")
for number in range(int(sys.argv[1])):
    node.send_output("joint_cmd", pa.array([0.0, float(number % 90)]))
print("burst sent", flush=True)
"""


@pytest.mark.parametrize("body", list(BODIES))
def test_a_burst_of_commands_is_not_dropped(tmp_path, body):
    burst = 5000
    with body_environment(body, tmp_path) as (body_env, _):
        dataflow = write_test_dataflow(tmp_path, sim_env={"SO101_LANG": "en", **body_env}, body=body)
        dora = DoraRun(dataflow, tmp_path / "dora.log", stop_after_s=120)
        try:
            dora.wait_for("SO-101 loaded", timeout_s=60)
            sender = subprocess.run(
                [sys.executable, "-c", BURST_SENDER, str(burst)], capture_output=True, text=True,
                env=dora_env(), timeout=60,
            )
            assert "burst sent" in sender.stdout, sender.stdout + sender.stderr
            deadline = time.monotonic() + 30
            while plain(dora.log()).count("joint 0 target -> ") < burst and time.monotonic() < deadline:
                time.sleep(0.2)
        finally:
            dora.stop()
    log = plain(dora.log())
    assert log.count("joint 0 target -> ") == burst
    assert "Discarding event for input `joint_cmd`" not in log
