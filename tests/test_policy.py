"""A trained policy in the dataflow: its features and units (so101/policy/features.py), its settings, the
policy environment (so101 policy-env), and `so101 eval --policy`'s refusals."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest

from so101.dataset.features import ACTION_KEY, ENVIRONMENT_KEY, IMAGE_KEY, STATE_KEY, WRIST_IMAGE_KEY, to_lerobot
from so101.policy.features import (
    inputs_for, joint_targets_deg, observation, picture_size_of, read_policy_features, unscaled_inputs,
)
from so101.policy.settings import PolicySettings
from so101.runtime.versions import library_version
from so101.tasks import CUBE_TO_BOX
from tests.helpers.dataflow import ROOT, SO101
# The fixtures live in conftest.py; the name stays here for tests/test_gym.py, which imports it from this module.
from tests.helpers.policies import policy_python  # noqa: F401

LIBRARY_VERSION = library_version()  # the dataflow's dora-rs: this environment's

NAMES = CUBE_TO_BOX.object_state_names
STATE_ONLY = {STATE_KEY: (6,), ENVIRONMENT_KEY: (len(NAMES),)}
ACTION = {ACTION_KEY: (6,)}


def write_config(folder, inputs, outputs=ACTION):
    folder.mkdir(parents=True, exist_ok=True)
    features = {key: {name: {"type": "STATE", "shape": list(shape)} for name, shape in features.items()}
                for key, features in (("input_features", inputs), ("output_features", outputs))}
    (folder / "config.json").write_text(json.dumps({"type": "act", **features}))
    return folder


# -- features and units -----------------------------------------------------------------------------------------

def test_a_state_only_policy_reads_the_arm_and_the_objects_and_a_vision_one_the_cameras_too():
    assert inputs_for(STATE_ONLY, ACTION, NAMES, None) == ("joint_state", "gripper_state", "object_state")
    seeing = {STATE_KEY: (6,), IMAGE_KEY: (3, 240, 320), WRIST_IMAGE_KEY: (3, 240, 320)}
    assert picture_size_of(seeing) == (320, 240) and picture_size_of(STATE_ONLY) is None
    assert inputs_for(seeing, ACTION, NAMES, (320, 240)) == ("joint_state", "gripper_state", "image", "wrist_image")


@pytest.mark.parametrize("inputs, outputs, size, message", [
    ({**STATE_ONLY, "observation.images.top": (3, 240, 320)}, ACTION, (320, 240),
     "the policy asks for observation.images.top, which this dataflow cannot give"),
    ({STATE_KEY: (14,)}, ACTION, None, "the policy's observation.state has shape (14,), this dataflow's (6,)"),
    ({ENVIRONMENT_KEY: (7,)}, ACTION, None, "observation.environment_state has shape (7,), this dataflow's (10,)"),
    (STATE_ONLY, {ACTION_KEY: (14,)}, None, "the policy's action has shape (14,), the SO-101's is (6,)"),
    ({IMAGE_KEY: (3, 96, 96)}, ACTION, None, "this dataflow has no pictures"),
    ({IMAGE_KEY: (3, 96, 96)}, ACTION, (320, 240), "has shape (3, 96, 96), this dataflow's (3, 240, 320)"),
])
def test_features_this_dataflow_cannot_give_are_refused_in_one_line_naming_them(inputs, outputs, size, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")) as refused:
        inputs_for(inputs, outputs, NAMES, size)
    assert "\n" not in str(refused.value)


def test_a_frame_becomes_lerobots_observation_and_an_action_the_bodys_degrees_exactly():
    arm_deg, gripper_deg = [10.0, -20.0, 30.5, -40.0, 50.0], [-10.0]
    objects = list(np.linspace(0.1, 1.0, len(NAMES)))
    picture = np.arange(8 * 6 * 3, dtype=np.uint8)
    values = observation({"joint_state": arm_deg, "gripper_state": gripper_deg, "object_state": objects,
                          "image": picture}, (8, 6))
    assert values[STATE_KEY].dtype == np.float32 and values[STATE_KEY].tolist() == to_lerobot(arm_deg + gripper_deg).tolist()
    assert values[STATE_KEY][5] == 0.0  # the gripper closed at -10° is LeRobot's 0
    assert values[ENVIRONMENT_KEY].tolist() == np.float32(objects).tolist()
    assert values[IMAGE_KEY].shape == (6, 8, 3) and values[IMAGE_KEY][0, 1].tolist() == [3, 4, 5]
    # Both ways: LeRobot's values back to degrees; the gripper's 0-100 is -10..100°.
    assert joint_targets_deg([10.0, -20.0, 30.5, -40.0, 50.0, 100.0]) == [10.0, -20.0, 30.5, -40.0, 50.0, 100.0]
    assert joint_targets_deg(np.array([[0, 0, 0, 0, 0, 0.0]]))[5] == -10.0
    assert joint_targets_deg(to_lerobot(arm_deg + [45.0])) == pytest.approx(arm_deg + [45.0], abs=1e-4)
    for bad in ([1, 2, 3], [0, 0, 0, 0, 0, float("nan")]):
        with pytest.raises(ValueError, match="expected 6 finite numbers"):
            joint_targets_deg(bad)


def test_a_policy_folders_features_are_read_from_its_config_without_lerobot(tmp_path):
    folder = write_config(tmp_path / "policy", STATE_ONLY)
    assert read_policy_features(folder) == (STATE_ONLY, ACTION)
    (tmp_path / "empty").mkdir()
    for where, message in ((tmp_path / "missing", "is not a folder"), (tmp_path / "empty", "has no config.json")):
        with pytest.raises(ValueError, match=message):
            read_policy_features(where)
    (folder / "config.json").write_text("{not json")
    with pytest.raises(ValueError, match="is not a LeRobot policy's config"):
        read_policy_features(folder)


def test_the_policy_nodes_settings_need_its_folder_and_refuse_a_device_torch_does_not_know():
    with pytest.raises(ValueError, match="SO101_POLICY_DIR is empty: set it"):
        PolicySettings.from_environ({})
    with pytest.raises(ValueError, match="SO101_POLICY_DEVICE: 'gpu' is not a torch device"):
        PolicySettings.from_environ({"SO101_POLICY_DIR": "/p", "SO101_POLICY_DEVICE": "gpu"})
    settings = PolicySettings.from_environ({"SO101_POLICY_DIR": "/p", "SO101_LOCKSTEP_PICTURES": "320x240"})
    assert (settings.device, settings.task, settings.image_size) == ("cpu", "cube_to_box", (320, 240))
    assert settings.real_cameras == ()  # a simulation's camera: it draws only when something moved, so is never stale
    assert PolicySettings.from_environ({"SO101_POLICY_DIR": "/p", "SO101_POLICY_CAMERAS": "front,wrist"}).real_cameras \
        == ("front", "wrist")
    with pytest.raises(ValueError, match="SO101_POLICY_CAMERAS: 'top' is not a camera: give front and/or wrist"):
        PolicySettings.from_environ({"SO101_POLICY_DIR": "/p", "SO101_POLICY_CAMERAS": "top"})


def test_the_policy_node_imports_nothing_of_the_projects_install_but_numpy_pyarrow_and_dora():
    # Its Python is the policy environment's, which has LeRobot, torch, dora-rs, pyarrow and numpy only.
    probe = ("import sys; sys.path.insert(0, 'nodes'); import policy; "
             "print(','.join(sorted({name.split('.')[0] for name in sys.modules})))")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=ROOT, check=True)
    loaded = set(done.stdout.strip().split(","))
    assert not loaded & {"pybullet", "mujoco", "av", "viser", "matplotlib", "yaml", "serial", "scservo_sdk",
                         "trimesh", "PIL", "torch", "lerobot"}
    assert {"dora", "pyarrow", "numpy", "so101"} <= loaded


# -- so101 eval --policy: refused before anything starts ---------------------------------------------------------

@pytest.mark.parametrize("make, extra, message", [
    (lambda tmp: tmp / "nothing", [], "is not a folder"),
    (lambda tmp: write_config(tmp / "other", {STATE_KEY: (14,)}), [], "observation.state has shape (14,)"),
    (lambda tmp: write_config(tmp / "fine", STATE_ONLY), ["--policy-python", "/no/python"], "/no/python does not exist"),
])
def test_eval_with_a_policy_it_cannot_run_says_why_in_one_line(tmp_path, make, extra, message):
    done = subprocess.run([str(SO101), "eval", "--task", "cube_to_box", "--policy", str(make(tmp_path)), *extra,
                           "--episodes", "1", "--lang", "en"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and message in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr


# -- the policy environment -------------------------------------------------------------------------------------

def test_a_python_without_lerobot_is_not_a_policy_environment_and_says_what_to_do(tmp_path):
    from so101.policy.environment import PolicyEnvError, check

    with pytest.raises(PolicyEnvError, match=r"cannot import what the policy node needs \(.*No module named") as refused:
        check(__import__("pathlib").Path(sys.executable))  # this project's Python: no torch, no LeRobot
    assert "so101 policy-env" in str(refused.value) and "\n" not in str(refused.value)
    with pytest.raises(PolicyEnvError, match="does not exist: make a policy environment"):
        check(tmp_path / "bin" / "python")


def python_with(folder, dora_version):
    """A Python environment made in `folder` with a stand-in `lerobot` package and, where `dora_version` is
    given, a stand-in dora-rs of that version (its distribution's metadata and a `dora` package)."""
    from so101.policy.environment import python_in

    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(folder)], check=True, timeout=60)
    (site,) = folder.glob("lib/python3*/site-packages")
    packages = {"lerobot": None} if dora_version is None else {"lerobot": None, "dora": dora_version}
    for package, version in packages.items():
        (site / package).mkdir()
        (site / package / "__init__.py").write_text("")
        if version is not None:
            (site / f"dora_rs-{version}.dist-info").mkdir()
            (site / f"dora_rs-{version}.dist-info" / "METADATA").write_text(f"Name: dora-rs\nVersion: {version}\n")
    return python_in(folder)


DORA_FIX = f"-m pip install 'dora-rs=={LIBRARY_VERSION}' (or make a policy environment with `so101 policy-env`)"


@pytest.mark.parametrize("dora_version, problem", [
    (None, "{python} has no dora-rs, which the policy node needs to join the dataflow: {python} " + DORA_FIX),
    ("1.0.0", f"{{python}} has dora-rs 1.0.0, but the dataflow runs dora-rs {LIBRARY_VERSION} and they must match: "
              "{python} " + DORA_FIX),
    (LIBRARY_VERSION, None),
])
def test_a_python_without_the_dataflows_dora_rs_is_named_with_the_command_that_fixes_it(tmp_path, dora_version, problem):
    from so101.policy.environment import dora_problem

    python = python_with(tmp_path / "env", dora_version)
    assert dora_problem(python) == (problem and problem.format(python=python))


@pytest.mark.parametrize("dora_version", [None, "1.0.0"])
@pytest.mark.parametrize("command, code", [("eval", 1), ("teleop", 2), ("policy-env", 1)])
def test_each_command_refuses_a_policy_python_without_the_dataflows_dora_rs_before_starting(tmp_path, dora_version,
                                                                                          command, code):
    from so101.policy.environment import REQUIREMENTS, STAMP_NAME, dora_problem

    folder = tmp_path / "env"
    python = python_with(folder, dora_version)
    log = tmp_path / "dora.log"
    policy = ["--task", "cube_to_box", "--policy", str(TINY_POLICY), "--policy-python", str(python), "--log", str(log)]
    arguments = {"eval": [*policy, "--episodes", "1", "--lang", "en"], "teleop": ["--mode", "direct", *policy, "--lang", "en"],
                 "policy-env": [str(folder)]}[command]
    (folder / STAMP_NAME).write_text(json.dumps({"requirements": list(REQUIREMENTS)}))  # built: policy-env only checks
    done = subprocess.run([str(SO101), command, *arguments], capture_output=True, text=True, timeout=60,
                          stdin=subprocess.DEVNULL)
    # so101 policy-env names only the pip command: making a policy environment is what it does itself.
    problem = dora_problem(python, or_policy_env=command != "policy-env")
    assert done.returncode == code and done.stderr == f"so101 {command}: {problem}\n", done.stderr
    assert not log.exists()  # no dataflow was started


def test_policy_env_leaves_a_folder_of_other_files_alone(tmp_path):
    keep = tmp_path / "notes.txt"
    keep.write_text("mine")
    done = subprocess.run([str(SO101), "policy-env", str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and "is a folder with files and no Python environment in it" in done.stderr
    assert keep.read_text() == "mine" and sorted(tmp_path.iterdir()) == [keep]


# -- the node against a real checkpoint, in the policy environment -----------------------------------------------

TINY_POLICY = ROOT / "tests" / "data" / "policy_act_tiny"  # how it was made: its README.md


def probe(python, frames, policy=TINY_POLICY, **env):
    asked = {"env": {"SO101_POLICY_DIR": str(policy), "SO101_LANG": "en", **env}, "frames": frames}
    done = subprocess.run([str(python), str(ROOT / "tests" / "helpers" / "policy_probe.py")], input=json.dumps(asked),
                          capture_output=True, text=True, timeout=300, env={**__import__("os").environ, "HF_HUB_OFFLINE": "1"})
    assert done.stdout.strip(), done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1]), done.stderr


def test_the_node_answers_each_frame_plays_its_chunk_out_and_resets_at_each_episode(policy_python):
    here, there = [10.0, -20.0, 30.0, 40.0, 0.0], [-30.0, 40.0, -10.0, 20.0, 60.0]
    objects = [0.2, 0.05, 0.02, 0.0, 0.0, 0.0, 1.0, -0.1, 0.2, 0.0]
    frames = [[1, 0, 7, here, [5.0], objects], [1, 1, 7, there, [90.0], objects], [1, 1, 7, there, [90.0], objects],
              [1, 2, 7, here, [5.0], objects], [2, 0, 8, here, [5.0], objects]]
    result, stderr = probe(policy_python, frames)
    assert result["code"] == 0, stderr
    answers = result["joint_cmd"]
    assert [answer[:2] for answer in answers] == [[1, 0], [1, 1], [1, 1], [1, 2], [2, 0]]
    first, second, again, third, next_episode = (answer[2] for answer in answers)
    assert all(len(targets) == 6 for targets in (first, second, third))
    # Frame 1 sent again gets the same answer, and does not use up the chunk's next action.
    assert again == second and len({tuple(first), tuple(second), tuple(third)}) == 3
    # A new episode resets the policy: the same observation at its frame 0 gets the first frame's answer
    # (without the reset, the chunk's fourth action would come).
    assert next_episode == first
    # In the body's units: the gripper within its −10…100°.
    assert all(-10.0 - 1e-6 <= targets[5] <= 100.0 + 1e-6 for targets in (first, second, third))


def test_a_policy_that_sees_answers_from_the_pictures_and_the_joints_alone(policy_python, seeing_policy):
    inputs, _ = read_policy_features(seeing_policy)
    assert ENVIRONMENT_KEY not in inputs and inputs[IMAGE_KEY] == inputs[WRIST_IMAGE_KEY] == (3, 24, 32)
    here = [10.0, -20.0, 30.0, 40.0, 0.0]
    dark, bright = [0] * (32 * 24 * 3), [255] * (32 * 24 * 3)
    # The same joints, other pictures: a new episode each, so that each answer is its chunk's first.
    frames = [[1, 0, 7, here, [5.0], None, dark, dark], [2, 0, 7, here, [5.0], None, bright, bright],
              [3, 0, 7, here, [5.0], None, dark, dark]]
    result, stderr = probe(policy_python, frames, seeing_policy, SO101_LOCKSTEP_PICTURES="32x24")
    assert result["code"] == 0, stderr
    from_dark, from_bright, dark_again = (answer[2] for answer in result["joint_cmd"])
    assert from_dark == dark_again and from_dark != from_bright  # what it sees moves its answer


def test_inference_that_fails_stops_the_node_in_one_line(policy_python):
    nan = float("nan")
    result, stderr = probe(policy_python, [[1, 0, 3, [nan] * 5, [nan], [nan] * 10]])
    assert result["code"] == 1 and result["joint_cmd"] == []
    assert "[policy] cannot go on: inference failed at frame 0 (seed 3): ValueError: the policy's action is" in stderr


@pytest.mark.parametrize("kind, reads", [
    ("state-only", "observation.environment_state (the simulator's object_state, which a real arm does not have)"),
    ("recipe", "observation.environment_state (from the perception node, which sees observation.images.front and the "
               "joints)"),
])
def test_eval_scores_a_policy_in_lockstep_episode_by_episode(policy_python, kind, reads, request):
    """A state policy reads the simulator's objects; a seeing recipe's (so101 learn --sees), the same policy
    behind its eyes: the body draws their front picture, and the perception node answers each frame."""
    policy = TINY_POLICY if kind == "state-only" else request.getfixturevalue("seeing_recipe")
    done = subprocess.run([str(SO101), "eval", "--task", "cube_to_box", "--policy", str(policy), "--policy-python",
                           str(policy_python), "--episodes", "2", "--seed", "5", "--time-limit", "2", "--lang", "en"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.strip().splitlines()
    # It was trained with ACT's default normalization (see test_inputs_a_policy_takes_unscaled_...), and is told so.
    assert lines[0] == ("so101 eval: note: the policy takes observation.environment_state unscaled (its config.json's "
                        "normalization_mapping has no ENV, as ACT's default): docs/loop/policy.md says what that costs "
                        "and how --policy.normalization_mapping scales it")
    # Its training dataset was on another machine: its joints' units cannot be known here, and it says so.
    assert lines[1] == ("so101 eval: note: the policy's joints are taken as degrees: its training dataset (/tmp/pyb100) "
                        "is not on this machine to say")
    assert lines[2] == f"so101 eval: the policy reads: observation.state, {reads}"
    assert lines[3].startswith(f"eval: cube_to_box on pybullet, the policy in {policy}, seeds 5..6")
    # 20 steps of training: it drives the arm for the whole time limit, and does not do the task.
    assert lines[4:7] == ["episode 0 (seed 5): failed (time limit, 2.0 s), 51 frames",
                          "episode 1 (seed 6): failed (time limit, 2.0 s), 51 frames",
                          "success: 0/2 (0%, 95% CI 0–66%, Wilson), mean time to success none (no success)"]
    # Its chunks are 10 actions: a new one at frames 0, 10, ... 50 of each episode, each timed.
    assert re.fullmatch(r"inference: 12 action chunks, median \d+ ms, 95th percentile \d+ ms, longest \d+ ms \(on cpu\)",
                        lines[7]), lines[7]


@pytest.mark.parametrize("learner", ["state policy", "seeing recipe"])
def test_demos_with_a_learner_write_the_experts_way_on_from_where_the_learner_left_the_arm(tmp_path, policy_python,
                                                                                          learner, request):
    """DAgger (so101 demos --learner): the learner drives until the takeover frame drawn from the seed (44 for seed
    21), unwritten; the expert finishes from there, and only its frames are written, the first of them where the
    learner left the arm. A seeing recipe drives behind its eyes, and what is written is what they found: its
    untrained eyes place the cube nowhere near the box the expert put it in."""
    import pyarrow.parquet as pq

    from so101.tasks.expert import takeover_frame

    folder = TINY_POLICY if learner == "state policy" else request.getfixturevalue("seeing_recipe")
    done = subprocess.run([str(SO101), "demos", str(tmp_path / "dagger"), "--task", "cube_to_box", "--episodes", "1",
                           "--seed", "21", "--no-video", "--learner", str(folder), "--policy-python", str(policy_python)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "taking over from the learner" in done.stdout.splitlines()[0]
    assert ("behind its eyes (front 32x24" in done.stdout.splitlines()[0]) == (learner == "seeing recipe")
    frames = int(re.search(r"^episode 0 \(seed 21\): success in [\d.]+ s, (\d+) frames, kept$", done.stdout, re.M).group(1))
    written = pq.read_table(next((tmp_path / "dagger" / "data").rglob("*.parquet"))).to_pydict()
    assert takeover_frame(21, 12.0, 25) == 44 and len(written["frame_index"]) == frames - 44
    assert max(abs(angle) for angle in written[STATE_KEY][0][:5]) > 3.0  # the learner moved the arm off home
    cube_xy, box_xy = np.array(written[ENVIRONMENT_KEY][-1][:2]), np.array(written[ENVIRONMENT_KEY][-1][7:9])
    assert (np.linalg.norm(cube_xy - box_xy) < 0.03) == (learner == "state policy")


def test_a_python_without_lerobot_refuses_the_policy_node_in_one_line(tmp_path):
    done = subprocess.run([str(SO101), "eval", "--task", "cube_to_box", "--policy", str(TINY_POLICY), "--policy-python",
                           sys.executable, "--episodes", "1", "--lang", "en"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 1, done.stdout + done.stderr
    assert re.search(r"^so101 eval: \[policy\] cannot start: LeRobot does not import in .*: run the node with a policy "
                     r"environment's Python \(so101 policy-env\)$", done.stderr.strip()), done.stderr



@pytest.mark.parametrize("mapping, unscaled", [
    (None, {STATE_KEY: "STATE", ENVIRONMENT_KEY: "ENV"}),
    ({"VISUAL": "MEAN_STD", "STATE": "MEAN_STD", "ACTION": "MEAN_STD"}, {ENVIRONMENT_KEY: "ENV"}),  # ACT's default
    ({"STATE": "MEAN_STD", "ENV": "IDENTITY", "ACTION": "MEAN_STD"}, {ENVIRONMENT_KEY: "ENV"}),
    ({"VISUAL": "MEAN_STD", "STATE": "MIN_MAX", "ENV": "MEAN_STD", "ACTION": "MEAN_STD"}, {}),
])
def test_inputs_a_policy_takes_unscaled_are_found_in_its_config(tmp_path, mapping, unscaled):
    config = {"type": "act", "input_features": {STATE_KEY: {"type": "STATE", "shape": [6]},
                                                ENVIRONMENT_KEY: {"type": "ENV", "shape": [len(NAMES)]},
                                                IMAGE_KEY: {"type": "VISUAL", "shape": [3, 96, 96]}},
              "output_features": {ACTION_KEY: {"type": "ACTION", "shape": [6]}}}
    if mapping is not None:
        config["normalization_mapping"] = mapping
    (tmp_path / "config.json").write_text(json.dumps(config))
    assert unscaled_inputs(tmp_path) == unscaled
    # The tiny checkpoint kept for the tests was trained with ACT's default, as LeRobot wrote it.
    assert unscaled_inputs(TINY_POLICY) == {ENVIRONMENT_KEY: "ENV"}

# -- at the prompt --------------------------------------------------------------------------------------------------

def test_the_prompt_says_how_to_ask_the_policy_and_without_one_how_to_start_it():
    from so101.prompt.commands import ParseError, RunPolicy, parse_command
    from so101.prompt.control import KeyboardControl
    from so101.prompt.poses import PoseStore

    assert parse_command("policy on", "en") == RunPolicy("on") and parse_command("POLICY Off", "en") == RunPolicy("off")
    for wrong in ("policy", "policy go", "policy on now"):
        assert parse_command(wrong, "en") == ParseError("  policy format: policy on (it drives) or policy off (it stops)")
    control = KeyboardControl(lambda angles: None, PoseStore(__import__("pathlib").Path("/nonexistent/poses.json")), "en")
    assert control.handle_line("policy on") == (["  no policy: start with so101 teleop --task cube_to_box --policy DIR"], False)
    told: list[str] = []
    control.tell_policy = told.append
    assert control.handle_line("policy on") == (["  → told the policy: on"], False) and told == ["on"]
    # A policy that answers before the reply is printed: its news still comes below the reply (the CI's 11-29 flake).
    screen: list[str] = []
    control.show_news = screen.append
    control.tell_policy = lambda word: control.on_event(
        {"type": "INPUT", "id": "policy_status", "value": __import__("pyarrow").array([f"[policy] act: {word}"])})
    control.hold_news()
    replies, _ = control.handle_line("policy off")
    screen.extend(replies)
    assert screen == ["  → told the policy: off"]
    control.release_news()  # at a terminal: once the next prompt is drawn
    assert screen == ["  → told the policy: off", "  [policy] act: off"]


@pytest.mark.skipif(__import__("shutil").which("tmux") is None, reason="tmux is not installed (.ci/run installs it)")
@pytest.mark.parametrize("kind", ["state-only", "seeing"])
def test_at_the_prompt_the_policy_drives_and_a_typed_command_takes_over(tmp_path, policy_python, kind, request):
    """The state-only policy reads the body's objects; the one that sees, the camera node's two pictures
    (drawn at 25 a second, the rate it learned from): `policy on` starts only once all it reads has come.
    (A seeing recipe at the prompt: tests/test_real_cameras.py, on the emulated arm.)"""
    import time

    from tests.helpers.terminal import start_teleop

    policy = TINY_POLICY if kind == "state-only" else request.getfixturevalue("seeing_policy")
    terminal, _, _ = start_teleop(tmp_path, "en", extra=f"--task cube_to_box --seed 3 --policy {policy} "
                                                         f"--policy-python {policy_python}", HF_HUB_OFFLINE="1")
    try:
        terminal.seen = terminal.wait_for_prompt(timeout_s=180).start()
        state = r"  joint angles now: \[(-?[\d.]+), (-?[\d.]+), (-?[\d.]+), (-?[\d.]+), (-?[\d.]+)\].*"
        assert all(abs(float(angle)) < 1.0 for angle in terminal.command("state", state).groups())  # home
        terminal.command("policy on", re.escape("  → told the policy: on"))
        terminal.wait_for(re.escape("  [policy] act is driving: any move you type takes over; policy off stops it"),
                          timeout_s=10, after=terminal.seen)
        time.sleep(3.0)
        assert not re.search(r"^> >", terminal.screen(), re.M), terminal.screen()  # news drew the prompt once
        driven = [float(angle) for angle in terminal.command("state", state).groups()]
        assert max(abs(angle) for angle in driven) > 2.0, driven  # the policy moved the arm
        terminal.command("0 40", re.escape("  → joint 0 (shoulder_pan) → 40°"))
        terminal.wait_for(re.escape("  [policy] a typed command took over: the policy stopped"), timeout_s=10,
                          after=terminal.seen)
        # What its inference cost while it drove: chunks of 10 actions, one every 40 ms, for about 3 s.
        chunks = terminal.wait_for(r"  \[policy\] this drive inferred (\d+) action chunks: median \d+ ms, longest \d+ ms "
                                   r"\(cpu\)", timeout_s=10, after=terminal.seen)
        assert 3 <= int(chunks.group(1)) <= 20, chunks.group(0)
        time.sleep(3.0)  # the policy sends nothing more: the arm stays where it was typed to
        assert abs(float(terminal.command("state", state).group(1)) - 40.0) < 2.0
        terminal.type_line("quit")
        terminal.wait_for(r"^TELEOP_EXIT=0$", timeout_s=60, after=terminal.seen)
    finally:
        terminal.close()


@pytest.mark.parametrize("extra, message", [
    ("--policy /nowhere", "so101 teleop: /nowhere is not a folder"),
    ("--policy {seeing}", "so101 teleop: the policy sees the task's cameras (the wrist's is drawn for a task's scene): "
                          "add --task cube_to_box"),
    ("--task cube_to_box --record {tmp}/seen --policy {seeing}",
     "so101 teleop: the policy sees 32x24 pictures, and one camera draws them for the recording too: record at "
     "--camera-size 32x24"),
    (f"--policy {TINY_POLICY} --policy-python /no/python", "so101 teleop: the policy reads a task's objects"),
    (f"--task cube_to_box --policy {TINY_POLICY} --policy-python /no/python", "so101 teleop: /no/python does not exist"),
    ("--policy-python /no/python", "so101 teleop: --policy-python goes with --policy DIR"),
])
def test_teleop_with_a_policy_it_cannot_run_says_why_in_one_line(tmp_path, extra, message):
    seeing = write_config(tmp_path / "seeing", {STATE_KEY: (6,), IMAGE_KEY: (3, 24, 32), WRIST_IMAGE_KEY: (3, 24, 32)})
    extra = extra.format(seeing=f"{seeing} --policy-python {sys.executable}", tmp=tmp_path)
    done = subprocess.run([str(SO101), "teleop", "--mode", "direct", "--lang", "en", *extra.split()],
                          capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert done.returncode == 2 and done.stderr.startswith(message) and len(done.stderr.strip().splitlines()) == 1, \
        done.stderr
