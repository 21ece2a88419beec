"""Two dataflows on one machine (issue 23), in tmux as a person runs them: the course's
`dora run dataflow.yml` and `so101 teleop`, in both orders, with the prompt started by hand.

dora 1.1's `dora run` takes prompts on one port only (53291): the one started second cannot be
joined, and a prompt meant for it would drive the first one's arm. Whichever comes second must say
so in one line, and `0 77` must move the arm of the prompt's own dataflow, not the other's.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import time
import uuid
from pathlib import Path

import pytest

from so101.bodies.registry import BODIES
from so101.runtime.cluster import CLUSTER_DATAFLOW
from so101.runtime.dataflow import LEADER_DATAFLOW_FILE, LEADER_NODE_ID, has_dynamic_node
from so101.runtime.processes import DAEMON_PORT_TAKEN_MARK, on_our_network, running_with_env
from tests.helpers.dataflow import PROMPT_COMMAND, DoraRun, write_test_dataflow
from tests.helpers.terminal import PROMPT_READY, Terminal, start_teleop

JOINT_0_TARGET_DEG = 77.0
COMMAND = f"0 {JOINT_0_TARGET_DEG:g}"
SENT = re.escape(f"  → joint 0 (shoulder_pan) → {JOINT_0_TARGET_DEG:g}°")


@pytest.mark.parametrize(
    ("dataflow_file", "started_node_id"),
    [*((body.dataflow_file, body.node_id) for body in BODIES.values()), (LEADER_DATAFLOW_FILE, LEADER_NODE_ID),
     (CLUSTER_DATAFLOW, "simulation")],
    ids=lambda value: value.name if isinstance(value, Path) else value,
)
def test_every_dataflow_file_waits_for_the_prompt_and_nothing_else(dataflow_file, started_node_id):
    assert has_dynamic_node(dataflow_file, "keyboard_control")
    assert not has_dynamic_node(dataflow_file, started_node_id)  # dora starts it: it has a path


@pytest.mark.parametrize("content", [None, "", "nodes: 3", "{not yaml"], ids=["missing", "empty", "no-list", "bad-yaml"])
def test_a_file_that_is_no_dataflow_waits_for_nothing(tmp_path, content):
    dataflow_file = tmp_path / "dataflow.yml"
    if content is not None:
        dataflow_file.write_text(content)
    assert not has_dynamic_node(dataflow_file, "keyboard_control")


def hand_started_prompt(tmp_path: Path) -> Terminal:
    """The course's second terminal: `python nodes/keyboard_control.py`."""
    env = {"SO101_LANG": "en", "SO101_POSES_FILE": str(tmp_path / "hand_poses.json"),
           "SO101_HISTORY_FILE": str(tmp_path / "hand_history"), "SO101_PROMPT_LOG": str(tmp_path / "hand_prompt.log")}
    return Terminal(" ".join(PROMPT_COMMAND), env)


def joint_0_reaches(terminal: Terminal, target_deg: float) -> float:
    """`state` at the prompt until joint 0 is within a degree of `target_deg` (30 s at most); its angle."""
    for _ in range(60):
        reply = terminal.command("state", r"  joint angles now: \[(.*?)\]°.*")
        angle_deg = float(reply.group(1).split(",")[0])
        if abs(angle_deg - target_deg) <= 1.0:
            return angle_deg
        time.sleep(0.5)
    raise AssertionError(f"joint 0 did not reach {target_deg}°: last state {reply.group(0)}")


@pytest.mark.skipif(os.geteuid() != 0 or shutil.which("unshare") is None, reason="needs root and unshare")
def test_a_process_in_another_network_namespace_cannot_hold_our_port():
    # A container's `dora run`, or a parallel test worker's, has a port 53291 of its own.
    elsewhere = subprocess.Popen(["unshare", "--net", "sleep", "30"])
    try:
        deadline = time.monotonic() + 10
        while on_our_network(elsewhere.pid) and time.monotonic() < deadline:  # until unshare has moved
            time.sleep(0.05)
        assert not on_our_network(elsewhere.pid)
    finally:
        elsewhere.kill()
        elsewhere.wait()
    assert on_our_network(os.getpid())
    assert on_our_network(elsewhere.pid)  # gone: what cannot be read counts as ours, the careful side


@pytest.mark.person
@pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux is not installed (.ci/run installs it)")
@pytest.mark.parametrize("course_first", [True, False], ids=["course-then-teleop", "teleop-then-course"])
def test_the_second_dataflow_says_so_and_each_prompt_drives_its_own_arm(tmp_path, no_other_dataflow, course_first):
    course_states = tmp_path / "course_joint_state.json"
    course_file = write_test_dataflow(tmp_path, {"SO101_LANG": "en"}, record_file=course_states)
    (tmp_path / "teleop").mkdir()
    terminals: list[Terminal] = []
    course = None
    marker = uuid.uuid4().hex  # in the environment of teleop and of everything it starts
    try:
        if course_first:
            course = DoraRun(course_file, tmp_path / "course.log", stop_after_s=300)
            course.wait_for("SO-101 loaded", timeout_s=120)
        teleop = start_teleop(tmp_path / "teleop", "en", SO101_TEST_RUN=marker)[0]
        terminals.append(teleop)
        if not course_first:
            teleop.seen = teleop.wait_for(PROMPT_READY, timeout_s=120).start()
            course = DoraRun(course_file, tmp_path / "course.log", stop_after_s=300)
            course.wait_for("SO-101 loaded", timeout_s=120)
            assert DAEMON_PORT_TAKEN_MARK in course.log()
        hand = hand_started_prompt(tmp_path)
        terminals.append(hand)

        course_named = f"`dora run {course_file} --stop-after 300s` in {tmp_path} (pid {course.process.pid})"
        if course_first:
            # teleop comes second: it refuses in one line naming the course's dataflow, and starts nothing
            refusal = teleop.wait_for(r"^so101 teleop: .*\nTELEOP_EXIT=2$").group(0)
            assert refusal.startswith("so101 teleop: another dataflow runs on this machine and holds the port a "
                                      "prompt joins by (53291, the only one dora 1.1's `dora run` takes): "
                                      f"{course_named}; a prompt started here would drive it."), refusal
            assert running_with_env("SO101_TEST_RUN", marker) == []
            driver = hand
        else:
            # the prompt by hand comes after the course's dataflow that cannot be joined: it refuses, naming both
            refusal = hand.wait_for(r"^cannot join .*\nTELEOP_EXIT=1$").group(0)
            teleop_pid = int(re.search(r"`so101 teleop [^`]*` \(pid (\d+)\)", refusal).group(1))
            assert refusal.startswith(
                "cannot join the dataflow as keyboard_control: two dataflows on this machine wait for one, and "
                "dora 1.1 lets it join only the one holding port 53291, `so101 teleop --body pybullet --mode direct "
                f"--lang en --log {tmp_path / 'teleop' / 'dora.log'}` (pid {teleop_pid}); {course_named} started "
                "after it and cannot be joined"), refusal
            driver = teleop
        driver.seen = driver.wait_for(PROMPT_READY, timeout_s=120, after=driver.seen).start()
        driver.command(COMMAND, SENT)
        joint_0_reaches(driver, JOINT_0_TARGET_DEG)
        time.sleep(1.0)  # the course's recorder hears a second more of its arm
    finally:
        for terminal in terminals:
            terminal.close()  # teleop stops its dataflow on the hang-up
        if course is not None:
            course.stop()
    course_joint_0_deg = json.loads(course_states.read_text())["samples"][-1][1][0]
    # the course's arm moved only for its own prompt
    assert course_joint_0_deg == pytest.approx(JOINT_0_TARGET_DEG if course_first else 0.0, abs=1.0)
    deadline = time.monotonic() + 30
    while running_with_env("SO101_TEST_RUN", marker) and time.monotonic() < deadline:
        time.sleep(0.5)
    assert running_with_env("SO101_TEST_RUN", marker) == []
