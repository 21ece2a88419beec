"""End to end, for every body: its real dataflow file under `dora run`, headless, commands typed into the prompt node."""

from __future__ import annotations

import pytest

from so101.bodies.registry import BODIES
from tests.helpers.dataflow import (
    DoraRun, body_environment, check_the_record, prompt_env, type_the_script, write_test_dataflow,
)

pytestmark = pytest.mark.dataflow


@pytest.mark.parametrize("body", list(BODIES))
def test_typed_commands_reach_their_targets(tmp_path, body):
    record_file = tmp_path / "joint_state.json"
    poses_file = tmp_path / "poses.json"
    with body_environment(body, tmp_path) as (body_env, _):
        dora = DoraRun(write_test_dataflow(tmp_path, body_env, record_file=record_file, body=body), tmp_path / "dora.log")
        try:
            dora.wait_for("SO-101", timeout_s=60)
            sent_at, end = type_the_script(tmp_path, prompt_env(tmp_path))
        finally:
            dora.stop()
    assert "Traceback" not in dora.log(), dora.log()[-3000:]
    check_the_record(record_file, poses_file, body, sent_at, end)
