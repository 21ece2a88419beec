"""The nodes' settings (so101/bodies/settings.py and the other nodes' settings modules): each declared once,
read as declared, and documented on its node's page (docs/nodes/) by a table made from the declarations
(docs/hooks.py), so no node's settings are left out and no table differs from the code.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from so101.bodies.registry import BODIES
from so101.bodies.scenario import Scenario
from so101.bodies.settings import (
    ArmSettings,
    MuJoCoSettings,
    NodeSettings,
    PyBulletSettings,
)
from so101.cameras.settings import RealCameraSettings
from so101.dataset.settings import RecorderSettings
from so101.runtime.settings import Setting, declared
from so101.tasks.settings import ExpertSettings
from tests.helpers.dataflow import ROOT
from tests.helpers.docs import hooks, page_text


def node_settings(body: str) -> tuple[Setting, ...]:
    return declared(NodeSettings) + declared(BODIES[body].settings)


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
def test_the_dataflow_file_sets_only_declared_settings(body):
    nodes = yaml.safe_load(BODIES[body].dataflow_file.read_text(encoding="utf-8"))["nodes"]
    env = next(node for node in nodes if node["id"] == BODIES[body].node_id)["env"]
    assert set(env) <= {setting.env_var for setting in node_settings(body)}


def test_an_empty_environment_gives_the_declared_defaults():
    assert NodeSettings.from_environ({}) == NodeSettings(
        display_mode="auto", image_hz=0.0, fast_steps=0, tick_log_path="", lang="zh", task="", seed=0,
        lockstep_fps=0, lockstep_pictures=None, scenario=Scenario(),
        lockstep_episode_frames=0)
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
    (NodeSettings, {"SO101_SCENARIO": '{"looks": "random"}'},
     "SO101_SCENARIO: a scenario's looks are one of fixed, varied, unseen, not 'random'"),
    (NodeSettings, {"SO101_SCENARIO": '{"physics": "wild"}'}, "unknown physics 'wild'; use fixed, varied, or a JSON file"),
    (NodeSettings, {"SO101_LANG": "fr"}, "unknown language 'fr' (from --lang or $SO101_LANG); use zh or en"),
    (PyBulletSettings, {"SO101_CONTROL": "torque"}, "unknown control mode 'torque'; use one of: position, servo"),
    (PyBulletSettings, {"SO101_SERVO_ZETA": "nan"}, "SO101_SERVO_ZETA='nan' is not a number >= 0"),
    (MuJoCoSettings, {"SO101_MUJOCO_DAMPING": "soft"}, "SO101_MUJOCO_DAMPING='soft' is not a number >= 0"),
    (ExpertSettings, {"SO101_EXPERT_MISSES": "1.5"}, "SO101_EXPERT_MISSES=1.5 is not a share from 0 to 1"),
    (RealCameraSettings, {"CAPTURE_PATH": "0", "SO101_CAMERA_FPS": "241"},
     "SO101_CAMERA_FPS=241 is not a frame rate from 1 to 240 per second"),
    (RealCameraSettings, {"CAPTURE_PATH": "0", "SO101_CAMERA_FPS": "0"},
     "SO101_CAMERA_FPS=0 is not a frame rate from 1 to 240 per second"),
    (RecorderSettings, {"SO101_RECORD_DIR": "d", "SO101_RECORD_FPS": "1001"},
     "SO101_RECORD_FPS=1001 is not a frame rate from 1 to 1000 per second"),
    (RecorderSettings, {"SO101_RECORD_DIR": "d", "SO101_RECORD_FPS": "thirty"},
     "SO101_RECORD_FPS='thirty' is not a whole number >= 0"),
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



def test_each_frame_rate_keeps_its_own_highest():
    """One reader (so101/runtime/settings.py), two bounds: a camera asks at most 240 per second, a recording 1000."""
    assert RealCameraSettings.from_environ({"CAPTURE_PATH": "0", "SO101_CAMERA_FPS": "240"}).fps == 240
    assert RecorderSettings.from_environ({"SO101_RECORD_DIR": "d", "SO101_RECORD_FPS": "1000"}).fps == 1000
    assert RecorderSettings.from_environ({"SO101_RECORD_DIR": "d", "SO101_RECORD_FPS": "1"}).fps == 1


# Each node file -> its reference page in docs/nodes/ and the settings classes its table is made from.
NODE_PAGES = {
    "simulation_node.py": ("simulation.md", ["so101.bodies.settings:NodeSettings", "so101.bodies.settings:PyBulletSettings"]),
    "simulation_mujoco.py": ("simulation_mujoco.md", ["so101.bodies.settings:NodeSettings",
                                                      "so101.bodies.settings:MuJoCoSettings"]),
    "arm_node.py": ("arm.md", ["so101.bodies.settings:ArmSettings"]),
    "keyboard_control.py": ("keyboard_control.md", ["so101.prompt.settings:PromptSettings"]),
    "recorder.py": ("recorder.md", ["so101.dataset.settings:RecorderSettings"]),
    "camera.py": ("camera.md", ["so101.dataset.settings:CameraSettings"]),
    "real_camera.py": ("real_camera.md", ["so101.cameras.settings:RealCameraSettings"]),
    "replay.py": ("replay.md", ["so101.dataset.settings:ReplaySettings"]),
    "leader_node.py": ("leader.md", ["so101.leader.settings:LeaderSettings"]),
    "web_view.py": ("web_view.md", ["so101.web.settings:WebViewSettings"]),
    "expert.py": ("expert.md", ["so101.tasks.settings:ExpertSettings"]),
    "episodes.py": ("episodes.md", ["so101.tasks.settings:EpisodeSettings"]),
    "policy.py": ("policy.md", ["so101.policy.settings:PolicySettings"]),
    "perception.py": ("perception.md", ["so101.perception.settings:PerceptionSettings"]),
}


def test_every_node_file_has_a_reference_page():
    assert sorted(NODE_PAGES) == sorted(path.name for path in (ROOT / "nodes").glob("*.py"))


def test_each_nodes_page_has_its_settings_table_and_its_dataflow_entry():
    for node_file, (page, class_paths) in NODE_PAGES.items():
        text = page_text(f"nodes/{page}")
        assert text.startswith("# ") and f"(`nodes/{node_file}`)" in text.splitlines()[0], page
        assert re.findall(r"^<!-- settings: (.*) -->$", text, re.MULTILINE) == [" ".join(class_paths)], page
        assert re.search(r"^<!-- dataflow-(node|made): .* -->$", text, re.MULTILINE), page


def test_each_body_page_names_every_setting_of_its_node():
    """A body node's page covers the shared loop's settings (NodeSettings) too, in its table or, for the real
    arm, in the arm node's table of what each one does there."""
    for body in BODIES:
        _, class_paths = NODE_PAGES[BODIES[body].node_file.name]
        covered = {each.env_var for path in class_paths for each in declared(hooks().settings_class(path))}
        if body == "real":
            covered |= set(re.findall(r"`(SO101_\w+)`", page_text("nodes/arm.md").split("| On the real arm |")[1]
                                      .split("\n\n")[0]))
        assert covered == {setting.env_var for setting in node_settings(body)}, body


def test_the_made_tables_are_the_declared_settings():
    """docs/hooks.py's table for a class: one row per declared setting, in order, with its default and meaning."""
    for class_path in sorted({path for _, paths in NODE_PAGES.values() for path in paths}):
        lines = hooks().settings_table([class_path]).splitlines()
        assert lines[0] == "| Environment variable | Default | Meaning |"
        rows = [[cell.strip() for cell in line.strip("|").split("|")] for line in lines[2:]]
        settings = declared(hooks().settings_class(class_path))
        assert [row[0] for row in rows] == [f"`{each.env_var}`" for each in settings], class_path
        for (_, default_cell, meaning_cell), each in zip(rows, settings):
            if not each.default:
                assert default_cell == ("empty (required)" if each.required else "empty"), each.env_var
            elif not each.default.startswith(str(ROOT)):
                assert default_cell == f"`{each.default}`", each.env_var
            assert meaning_cell == each.meaning.replace("|", "&#124;"), each.env_var


def test_a_default_inside_the_checkout_is_shown_beside_dataflow_yml():
    from so101.prompt.settings import PromptSettings

    made = hooks().settings_table(["so101.prompt.settings:PromptSettings"])
    poses_file = next(each for each in declared(PromptSettings) if each.env_var == "SO101_POSES_FILE")
    assert poses_file.default.startswith(str(ROOT))
    assert "| `SO101_POSES_FILE` | `saved_poses.json` beside `dataflow.yml` |" in made
    assert str(ROOT) not in made


def test_a_task_is_read_by_name_and_an_unknown_one_is_refused_in_one_line():
    settings = NodeSettings.from_environ({"SO101_TASK": " cube_to_box ", "SO101_SEED": "12"})
    assert (settings.task, settings.seed) == ("cube_to_box", 12)
    from so101.tasks import CUBE_TO_BOX, task_for_setting

    # The body node asks the tasks for the one named (nodes/simulation_node.py): bodies know no task.
    assert task_for_setting(settings.task) is CUBE_TO_BOX and task_for_setting("") is None
    with pytest.raises(ValueError, match=r"^SO101_TASK: unknown task 'cubes'; the tasks are: cube_to_box$"):
        task_for_setting(NodeSettings.from_environ({"SO101_TASK": "cubes"}).task)
    with pytest.raises(ValueError, match=r"^SO101_SEED='-1' is not a whole number >= 0$"):
        NodeSettings.from_environ({"SO101_SEED": "-1"})


def test_the_real_arm_refuses_a_task():
    from so101.bodies.real_arm import check_node_settings

    with pytest.raises(ValueError, match="the real arm has no task scene .* SO101_TASK=cube_to_box is for a simulation"):
        check_node_settings(NodeSettings.from_environ({"SO101_TASK": "cube_to_box"}))
