"""End to end: the real dataflow.yml under `dora run`, headless, commands typed into the prompt node."""

from __future__ import annotations

import json
import subprocess
import time

import pytest

from tests.dataflow_helpers import PROMPT_COMMAND, DoraRun, prompt_env, write_test_dataflow

pytestmark = pytest.mark.dataflow

SETTLE_S = 1.5  # 90° at the course's 3 rad/s takes 0.52 s; the rest is margin

# (command, expected arm angles in degrees once it has settled)
SCRIPT = [
    ("0 90", [90, 0, 0, 0, 0]),
    ("batch -30 45 -60 30 0", [-30, 45, -60, 30, 0]),
    ("save a", [-30, 45, -60, 30, 0]),
    ("home", [0, 0, 0, 0, 0]),
    ("go a", [-30, 45, -60, 30, 0]),
]


def test_typed_commands_reach_their_targets(tmp_path):
    record_file = tmp_path / "joint_state.json"
    poses_file = tmp_path / "poses.json"
    dora = DoraRun(write_test_dataflow(tmp_path, record_file=record_file), tmp_path / "dora.log")
    try:
        dora.wait_for("SO-101", timeout_s=60)
        prompt = subprocess.Popen(
            PROMPT_COMMAND, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            env=prompt_env(tmp_path), cwd=tmp_path,
        )
        sent_at = []
        for command, _ in SCRIPT:
            time.sleep(SETTLE_S if sent_at else 1.0)
            sent_at.append(time.monotonic())
            prompt.stdin.write(command + "\n")
            prompt.stdin.flush()
        time.sleep(SETTLE_S)
        end = time.monotonic()
        prompt.stdin.close()
        prompt_output = prompt.stdout.read()
        assert prompt.wait(20) == 0, prompt_output
    finally:
        dora.stop()
    assert "Traceback" not in prompt_output, prompt_output
    assert "Traceback" not in dora.log(), dora.log()[-3000:]

    samples = json.loads(record_file.read_text())["samples"]
    windows = list(zip(sent_at, sent_at[1:] + [end]))
    for (command, expected), (start, stop) in zip(SCRIPT, windows):
        in_window = [state for t, state in samples if start < t < stop]
        assert in_window, f"no joint_state between sending {command!r} and the next command"
        reached = in_window[-1]
        for angle, target in zip(reached, expected):
            assert abs(angle - target) <= 1.0, f"after {command!r}: {reached} is not within 1° of {expected}"

    # `save a` stored the state it had reached, from joint_state: the batch's angles within 1°.
    saved = json.loads(poses_file.read_text())
    assert list(saved) == ["a"]
    assert saved["a"]["joints_deg"] == pytest.approx([-30, 45, -60, 30, 0], abs=1.0)
