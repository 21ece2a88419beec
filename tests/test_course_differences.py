"""Evidence for docs/differences.md, "Where this project differs from the course": what dora-rs 1.1 does with the course's files."""

from __future__ import annotations

import subprocess

import pytest

from tests.helpers.dataflow import VENV_BIN, dora_env

pytestmark = pytest.mark.dataflow

# The shape of the course's dataflow.yml (section 10.2, step D): nodes declared under `custom:`.
COURSE_STYLE_DATAFLOW = """\
nodes:
  - id: simulation
    custom:
      source: simulation_node.py
      inputs:
        tick: dora/timer/millis/4
      outputs:
        - joint_state
"""

# A node that, like the course's keyboard_control, reads its commands with input().
READS_STDIN = """\
import os
from dora import Node

node = Node()
try:
    print(f"read {input()!r}", flush=True)
except EOFError:
    print(f"input() got end of file; stdin is {os.readlink('/proc/self/fd/0')}", flush=True)
try:
    open("/dev/tty").read(1)
except OSError as error:
    print(f"/dev/tty cannot be read: {type(error).__name__}", flush=True)
"""


def dora_run(tmp_path, dataflow_text: str) -> subprocess.CompletedProcess:
    dataflow = tmp_path / "dataflow.yml"
    dataflow.write_text(dataflow_text)
    return subprocess.run(
        [str(VENV_BIN / "dora"), "run", str(dataflow), "--stop-after", "3s"],
        cwd=tmp_path, capture_output=True, text=True, env=dora_env(), timeout=60,
    )


def test_the_courses_custom_source_syntax_is_refused_by_dora_1_1(tmp_path):
    result = dora_run(tmp_path, COURSE_STYLE_DATAFLOW)
    assert result.returncode != 0
    assert "nodes[0]: unknown field `custom`, expected one of `id`" in result.stdout + result.stderr


def test_a_node_started_by_dora_run_cannot_read_the_keyboard(tmp_path):
    (tmp_path / "reader.py").write_text(READS_STDIN)
    result = dora_run(tmp_path, "nodes:\n  - id: reader\n    path: reader.py\n    inputs:\n      tick: dora/timer/millis/100\n")
    output = result.stdout + result.stderr
    assert "input() got end of file; stdin is /dev/null" in output, output[-2000:]
    assert "/dev/tty cannot be read: OSError" in output
