"""The body nodes' settings (so101/bodies/settings.py): each declared once, read as declared, and
documented in the README's table of its node, no more and no less.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from so101.bodies.registry import BODIES, DEFAULT_BODY
from so101.bodies.settings import (
    ArmSettings,
    MuJoCoSettings,
    NodeSettings,
    PyBulletSettings,
)
from so101.runtime.settings import Setting, declared
from tests.helpers.dataflow import ROOT

# Each body node's table of environment variables in the README: the heading of the section it is in.
README_SECTIONS = {
    "pybullet": "### simulation (`nodes/simulation_node.py`)",
    "mujoco": "## MuJoCo: the same contract, another body",
    "real": "## The real arm: swap one driver node",
}
TABLE_HEADER = "| Environment variable | Default | Meaning |"


def node_settings(body: str) -> tuple[Setting, ...]:
    return declared(NodeSettings) + declared(BODIES[body].settings)


def readme_table(heading: str) -> list[tuple[list[str], str, str]]:
    """(the SO101_* variables a row names, its Default cell, its Meaning cell) for each row of the
    section's one table of environment variables."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    level = heading.split(" ")[0]
    section = text[text.index(heading + "\n"):]
    end = re.search(rf"^#{{1,{len(level)}}} ", section[len(heading):], re.MULTILINE)
    section = section[: len(heading) + end.start()] if end else section
    lines = section.splitlines()
    assert lines.count(TABLE_HEADER) == 1, heading
    start = lines.index(TABLE_HEADER)
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        cells = [cell.strip() for cell in line.strip("|").split("|")]
        rows.append((re.findall(r"`(SO101_\w+)`", cells[0]), cells[1], cells[2]))
    return rows


def test_every_body_names_its_settings_class():
    assert {name: body.settings for name, body in BODIES.items()} == {
        "pybullet": PyBulletSettings, "mujoco": MuJoCoSettings, "real": ArmSettings,
    }


@pytest.mark.parametrize("body", list(BODIES))
def test_no_variable_is_declared_twice_for_a_node(body):
    names = [setting.env_var for setting in node_settings(body)]
    assert len(names) == len(set(names))
    assert all(name.startswith("SO101_") for name in names)


@pytest.mark.parametrize("body", list(BODIES))
def test_the_readme_documents_each_nodes_settings_and_no_others(body):
    rows = readme_table(README_SECTIONS[body])
    documented = [name for names, _, _ in rows for name in names]
    assert sorted(documented) == sorted(setting.env_var for setting in node_settings(body))
    settings = {setting.env_var: setting for setting in node_settings(body)}
    # The shared loop's settings are told in full in the course's node's table; the others say "as for".
    told_here = {setting.env_var for setting in declared(BODIES[body].settings)}
    if body == DEFAULT_BODY:
        told_here |= {setting.env_var for setting in declared(NodeSettings)}
    for names, default_cell, meaning_cell in rows:
        if default_cell.startswith("as for"):
            continue
        for name in names:
            # The default: "empty" for an empty one, else the value itself.
            if settings[name].default:
                assert f"`{settings[name].default}`" in default_cell, name
            else:
                assert default_cell.startswith("empty"), name
        if len(names) == 1 and names[0] in told_here:
            assert meaning_cell == settings[names[0]].meaning, names[0]


@pytest.mark.parametrize("body", list(BODIES))
def test_the_dataflow_file_sets_only_declared_settings(body):
    nodes = yaml.safe_load(BODIES[body].dataflow_file.read_text(encoding="utf-8"))["nodes"]
    env = next(node for node in nodes if node["id"] == BODIES[body].node_id)["env"]
    assert set(env) <= {setting.env_var for setting in node_settings(body)}


def test_an_empty_environment_gives_the_declared_defaults():
    assert NodeSettings.from_environ({}) == NodeSettings(
        display_mode="auto", image_hz=0.0, fast_steps=0, tick_log_path="", lang="zh", task="", seed=0,
        lockstep_fps=0, lockstep_pictures=None, lockstep_episode_frames=0)
    assert PyBulletSettings.from_environ({}) == PyBulletSettings(
        assets_dir=None, control_mode="position", servo_damping_ratio=0.7)
    assert MuJoCoSettings.from_environ({}) == MuJoCoSettings(assets_dir=None, joint_damping_n_m_s=None)


def test_the_arm_settings_read_every_variable():
    settings = ArmSettings.from_environ({
        "SO101_PORT": " /dev/ttyUSB0 ", "SO101_CALIBRATION": "~/arm.json", "SO101_MAX_SPEED_DEG_S": "15",
        "SO101_JOINT_SIGNS": "1,-1,1,1,1,1", "SO101_TORQUE_LIMIT": "20", "SO101_BUS_RETRIES": "3",
    })
    assert settings == ArmSettings(
        port="/dev/ttyUSB0", calibration_file=Path("~/arm.json").expanduser(), max_speed_deg_s=15.0,
        joint_signs=(1, -1, 1, 1, 1, 1), torque_limit_percent=20.0, retries=3,
    )
    defaults = ArmSettings.from_environ({"SO101_PORT": "/dev/ttyACM0", "SO101_CALIBRATION": "c.json"})
    assert (defaults.max_speed_deg_s, defaults.joint_signs, defaults.torque_limit_percent, defaults.retries) == (
        90.0, (1,) * 6, 100.0, 5)


@pytest.mark.parametrize("settings_class, environ, message", [
    (NodeSettings, {"SO101_IMAGE_HZ": "-1"}, "SO101_IMAGE_HZ='-1' is not a number >= 0"),
    (NodeSettings, {"SO101_FAST_STEPS": "2.5"}, "SO101_FAST_STEPS='2.5' is not a whole number >= 0"),
    (NodeSettings, {"SO101_LANG": "fr"}, "unknown language 'fr' (from --lang or $SO101_LANG); use zh or en"),
    (PyBulletSettings, {"SO101_CONTROL": "torque"}, "unknown control mode 'torque'; use one of: position, servo"),
    (PyBulletSettings, {"SO101_SERVO_ZETA": "nan"}, "SO101_SERVO_ZETA='nan' is not a number >= 0"),
    (MuJoCoSettings, {"SO101_MUJOCO_DAMPING": "soft"}, "SO101_MUJOCO_DAMPING='soft' is not a number >= 0"),
    (ArmSettings, {"SO101_PORT": "p", "SO101_CALIBRATION": "c", "SO101_TORQUE_LIMIT": "120"},
     "SO101_TORQUE_LIMIT=120 is above 100 (a percentage of the servo's maximum)"),
    (ArmSettings, {"SO101_PORT": "p", "SO101_CALIBRATION": "c", "SO101_JOINT_SIGNS": "1,1"},
     "SO101_JOINT_SIGNS='1,1': expected 6 values of 1 or -1"),
    (ArmSettings, {"SO101_PORT": "/dev/ttyUSB1"},
     "SO101_CALIBRATION is empty: set it (the dataflow's env:, or so101 teleop --calibration) to the arm's "
     "calibration file; make one with `so101 calibrate --port /dev/ttyUSB1 --out FILE`"),
])
def test_a_bad_value_is_one_line_naming_it(settings_class, environ, message):
    with pytest.raises(ValueError) as raised:
        settings_class.from_environ(environ)
    assert message in str(raised.value) and "\n" not in str(raised.value)



# The other nodes' settings (recording, replay, the leader), each class against its node's table in the README.
OTHER_NODES = {
    "### recorder (`nodes/recorder.py`)": "so101.dataset.settings:RecorderSettings",
    "### camera (`nodes/camera.py`)": "so101.dataset.settings:CameraSettings",
    "### replay (`nodes/replay.py`)": "so101.dataset.settings:ReplaySettings",
    "### leader (`nodes/leader_node.py`)": "so101.leader.settings:LeaderSettings",
    "### web_view (`nodes/web_view.py`)": "so101.web.settings:WebViewSettings",
    "### expert (`nodes/expert.py`)": "so101.tasks.settings:ExpertSettings",
    "### episodes (`nodes/episodes.py`)": "so101.tasks.settings:EpisodeSettings",
    "### policy (`nodes/policy.py`)": "so101.policy.settings:PolicySettings",
}


@pytest.mark.parametrize("heading, class_path", list(OTHER_NODES.items()))
def test_the_readme_documents_the_other_nodes_settings(heading, class_path):
    import importlib

    module, class_name = class_path.split(":")
    declared_settings = declared(getattr(importlib.import_module(module), class_name))
    rows = readme_table(heading)
    assert sorted(name for names, _, _ in rows for name in names) == sorted(each.env_var for each in declared_settings)
    by_name = {each.env_var: each for each in declared_settings}
    for names, default_cell, meaning_cell in rows:
        (name,) = names
        assert (f"`{by_name[name].default}`" in default_cell) if by_name[name].default else default_cell.startswith("empty")
        assert meaning_cell == by_name[name].meaning, name


def test_a_task_is_read_by_name_and_an_unknown_one_is_refused_in_one_line():
    settings = NodeSettings.from_environ({"SO101_TASK": " cube_to_box ", "SO101_SEED": "12"})
    assert (settings.task, settings.seed) == ("cube_to_box", 12)
    with pytest.raises(ValueError, match=r"^SO101_TASK: unknown task 'cubes'; the tasks are: cube_to_box$"):
        NodeSettings.from_environ({"SO101_TASK": "cubes"})
    with pytest.raises(ValueError, match=r"^SO101_SEED='-1' is not a whole number >= 0$"):
        NodeSettings.from_environ({"SO101_SEED": "-1"})


def test_the_real_arm_refuses_a_task():
    from so101.bodies.real_arm import check_node_settings

    with pytest.raises(ValueError, match="the real arm has no task scene .* SO101_TASK=cube_to_box is for a simulation"):
        check_node_settings(NodeSettings.from_environ({"SO101_TASK": "cube_to_box"}))
