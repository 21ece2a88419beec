"""dataflow.yml keeps the course's contract: node ids, inputs, outputs, and the queues the nodes rely on."""

from __future__ import annotations

from pathlib import PurePosixPath

import yaml

from so101.leader.settings import LeaderSettings
from so101.runtime.dataflow import TICK_PERIOD_S, timer_period_s, with_leader
from so101.runtime.settings import declared
from tests.helpers.dataflow import ROOT

DATAFLOW = yaml.safe_load((ROOT / "dataflow.yml").read_text(encoding="utf-8"))
NODES = {node["id"]: node for node in DATAFLOW["nodes"]}


def test_the_two_course_nodes_and_nothing_else():
    assert list(NODES) == ["keyboard_control", "simulation"]
    assert NODES["keyboard_control"]["path"] == "dynamic"  # `dora run` gives started nodes no keyboard
    assert NODES["simulation"]["path"] == "nodes/simulation_node.py"
    assert (ROOT / NODES["simulation"]["path"]).is_file()


def test_the_simulation_is_stepped_by_a_fresh_4_ms_tick_and_keeps_every_command():
    inputs = NODES["simulation"]["inputs"]
    assert inputs["tick"] == {"source": "dora/timer/millis/4", "queue_size": 1}
    assert timer_period_s({"inputs": inputs}) == 0.004 == TICK_PERIOD_S  # the tools that step without dora use it
    assert inputs["joint_cmd"]["source"] == "keyboard_control/joint_cmd"
    assert inputs["joint_cmd"]["queue_policy"] == "backpressure"
    assert NODES["simulation"]["outputs"] == ["joint_state", "gripper_state", "image"]
    assert NODES["simulation"]["restart_policy"] == "never"


def test_the_prompt_sends_joint_cmd_and_hears_the_state():
    prompt = NODES["keyboard_control"]
    assert prompt["outputs"] == ["joint_cmd"]
    # The prompt keeps the latest state but reads them all: 1 s of them queue while it waits for
    # the CPU, where a queue of one dropped states with a warning line each in its log (and one of
    # 0.4 s did, with another test's dataflow beside it on 2 cores).
    assert prompt["inputs"] == {
        "joint_state": {"source": "simulation/joint_state", "queue_size": 250},
        "gripper_state": {"source": "simulation/gripper_state", "queue_size": 250},
    }


def test_every_simulation_setting_is_declared_with_its_default():
    env = NODES["simulation"]["env"]
    assert env == {
        "SO101_MODE": "auto", "SO101_CONTROL": "position", "SO101_SERVO_ZETA": "0.7", "SO101_IMAGE_HZ": "0",
        "SO101_FAST_STEPS": "0", "SO101_TICK_LOG": "", "SO101_LANG": "zh",
    }


def test_the_leader_dataflow_is_the_course_graph_with_the_leader_driving():
    """dataflow_leader.yml is what `so101 teleop --leader` derives from dataflow.yml (with_leader), so
    the file a student reads is the graph teleop runs."""
    leader_file = yaml.safe_load((ROOT / "dataflow_leader.yml").read_text(encoding="utf-8"))
    file_env = next(node for node in leader_file["nodes"] if node["id"] == "leader")["env"]
    derived = with_leader(yaml.safe_load((ROOT / "dataflow.yml").read_text(encoding="utf-8")), "simulation",
                          file_env, root=PurePosixPath("."))
    for node in derived["nodes"]:
        if node["path"] != "dynamic":
            node["path"] = str(PurePosixPath(node["path"]))
    assert derived == leader_file
    leader = next(node for node in leader_file["nodes"] if node["id"] == "leader")
    assert timer_period_s(leader) == 0.010  # the 10 ms tick
    assert set(file_env) == {setting.env_var for setting in declared(LeaderSettings)}
