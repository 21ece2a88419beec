"""Every body speaks the same contract: registered once, the same graph, the same facts.

A body node added under nodes/ without an entry in so101.bodies.registry would escape the
contract suite (the `body` fixture of tests/test_simulation_node.py runs over that table):
the first test fails then.
"""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree

import numpy as np
import pytest
import yaml

from so101 import assets
from so101.bodies.registry import BODIES, DEFAULT_BODY
from so101.robot import ACTUATED_JOINTS
from tests.helpers.dataflow import ROOT


def test_every_body_node_is_registered():
    # The nodes that are not bodies: the prompt, recording's and replay's, the leader arm, the web view, the
    # expert, the episodes' runner, the trained policy, its eyes and the real arm's USB cameras.
    others = {"keyboard_control.py", "recorder.py", "camera.py", "replay.py", "leader_node.py", "web_view.py",
              "expert.py", "episodes.py", "policy.py", "perception.py", "real_camera.py"}
    node_files = sorted(path for path in (ROOT / "nodes").glob("*.py") if path.name not in others)
    assert node_files == sorted(body.node_file for body in BODIES.values())
    assert DEFAULT_BODY == "pybullet"  # the course's choice


def graph(body):
    """The body's dataflow without what may differ between bodies: the body node's id, path,
    env and tick period (the real arm's bus ticks at 50 Hz), and the camera the real arm lacks."""
    nodes = yaml.safe_load(body.dataflow_file.read_text(encoding="utf-8"))["nodes"]
    for node in nodes:
        if node["id"] == body.node_id:
            node["id"] = "simulation"
            node.pop("path")
            node.pop("env")
            node["inputs"]["tick"].pop("source")
            node["outputs"] = [output for output in node["outputs"] if output != "image"]
        for spec in node.get("inputs", {}).values():
            if "source" in spec:
                spec["source"] = spec["source"].replace(f"{body.node_id}/", "simulation/")
    return nodes


@pytest.mark.parametrize("name", list(BODIES))
def test_each_body_has_the_courses_graph(name):
    body = BODIES[name]
    assert body.dataflow_file.is_file() and body.node_file.is_file()
    assert graph(body) == graph(BODIES[DEFAULT_BODY])
    node = next(node for node in yaml.safe_load(body.dataflow_file.read_text())["nodes"] if node["id"] == body.node_id)
    assert (ROOT / node["path"]) == body.node_file


def test_the_joint_facts_equal_the_mjcf():
    from so101.bodies.mujoco_sim import SO101MuJoCo

    with SO101MuJoCo(mode="direct", renders=False, log=lambda message: None) as sim:
        model = sim.model
        assert sim.joint_names == [joint.name for joint in ACTUATED_JOINTS]  # names and order
        for joint in ACTUATED_JOINTS:
            # The MJCF gives the ranges with more digits than the URDF (so101.robot's source):
            # shoulder_pan is ±110° there, ±1.91986 rad = ±109.9999° in the URDF.
            low, high = np.degrees(model.joint(joint.name).range)
            assert (low, high) == pytest.approx((joint.lower_deg, joint.upper_deg), abs=1e-3), joint.name
            # The servo's command range, as the MJCF declares it (5 decimals there).
            ctrl_low, ctrl_high = np.degrees(model.actuator(joint.name).ctrlrange)
            assert (ctrl_low, ctrl_high) == pytest.approx((joint.lower_deg, joint.upper_deg), abs=1e-3), joint.name
    # The file itself, not only what MuJoCo made of it.
    worldbody = ElementTree.parse(assets.mjcf_path()).getroot().find("worldbody")  # not the <default> classes
    declared = [element.get("name") for element in worldbody.iter("joint")]
    assert declared == [joint.name for joint in ACTUATED_JOINTS]


def test_without_damping_the_mujoco_arm_overshoots_more():
    from so101.bodies.mujoco_sim import SO101MuJoCo

    def peak_deg(damping):
        with SO101MuJoCo(mode="direct", renders=False, joint_damping_n_m_s=damping, log=lambda message: None) as sim:
            sim.set_targets_deg([90, 0, 0, 0, 0, 0])
            peak = 0.0
            for _ in range(375):  # 1.5 s
                sim.step()
                peak = max(peak, sim.joint_angles_deg()[0])
            return peak, sim.joint_damping_n_m_s()

    with_mjcf_damping, damping = peak_deg(None)
    without, _ = peak_deg(0.0)
    assert damping == pytest.approx(0.60)  # the STS3215 class's
    assert with_mjcf_damping > 90.0  # MuJoCo's servo is a spring: even damped it overshoots a little
    assert without > with_mjcf_damping + 10.0  # and without damping it swings far past


def test_so101_teleop_knows_every_loaded_line():
    # teleop waits for this line (so101.runtime.dataflow.LOADED_MARKS) without importing the loop's module.
    from so101.bodies.node_loop import TAGS, TEXT
    from so101.runtime.dataflow import LOADED_MARKS

    for lang, text in TEXT.items():
        for tags in TAGS.values():
            loaded = text["loaded"].format(tag=tags[lang], identity="robot_id = 1", mode="DIRECT", step_ms=4, detail="x")
            assert any(mark in loaded for mark in LOADED_MARKS), lang


@pytest.mark.parametrize("bad", [[0.0] * 5, [0.0] * 7, [0, 0, 0, float("nan"), 0, 0], "123456", None])
def test_every_body_refuses_the_same_bad_goals(bad):
    from so101.robot import goal_deg

    with pytest.raises(ValueError, match="expected 6 finite angles in degrees"):
        goal_deg(bad)
    assert goal_deg([1, 2, 3, 4, 5, 6]) == (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
