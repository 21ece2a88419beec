"""The task as a Gymnasium environment (so101/gym/): its pure core, Gymnasium's own conformance check on
both bodies and every observation type, seeded determinism, the layouts of so101 eval, the expert
through the API, vector environments, EnvHub's make_env and LeRobot's lerobot-eval on a checkpoint."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tomllib
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import so101.gym
from so101.dataset.features import GRIPPER_RANGE, to_lerobot
from so101.gym import ENV_ID, MAX_EPISODE_STEPS
from so101.gym.cube_to_box import CubeToBoxEnv
from so101.gym.expert import ExpertPolicy, run_episode
from so101.gym.spaces import (
    JOINT_OVERSHOOT_DEG, action_space, agent_pos_space, check_camera_size, clamped_targets_deg, environment_state_space,
    observation_space, step_outcome,
)
from so101.policy.environment import with_checkout
from so101.robot import ACTUATED_JOINTS, HOME_POSE_DEG
from so101.tasks import CUBE_TO_BOX
from so101.tasks.expert import seen_in
from tests.helpers.dataflow import ROOT
from tests.test_policy import TINY_POLICY, policy_python  # noqa: F401  (the policy environment's fixture)

BODIES = ("pybullet", "mujoco")
OBS_TYPES = ("state", "pixels_agent_pos", "all")
SMALL = (64, 48)  # pictures small enough to draw quickly


def make(body="pybullet", **options):
    return gymnasium.make(ENV_ID, body=body, camera_size=options.pop("camera_size", SMALL), **options)


# -- the pure core -----------------------------------------------------------------------------------------------

def test_the_action_is_six_joint_targets_in_lerobots_units_within_the_joints_limits():
    space = action_space()
    assert space.shape == (6,) and space.dtype == np.float32
    # The arm in degrees, the URDF's limits; the gripper 0-100 (its -10°..100° mapped, to 0.0001).
    assert space.low[0] == pytest.approx(-110.0, abs=1e-3) and space.high[4] == pytest.approx(162.8, abs=0.1)
    assert (space.low[5], space.high[5]) == pytest.approx(GRIPPER_RANGE, abs=1e-3)
    # Beyond the limits, as every driver is: clamped; inside, the same degrees back.
    assert clamped_targets_deg([500.0, -500.0, 0.0, 0.0, 0.0, 150.0]) == pytest.approx(
        (ACTUATED_JOINTS[0].upper_deg, ACTUATED_JOINTS[1].lower_deg, 0.0, 0.0, 0.0, ACTUATED_JOINTS[5].upper_deg))
    assert clamped_targets_deg(to_lerobot([10.0, -20.0, 30.0, -40.0, 50.0, 45.0])) == pytest.approx(
        (10.0, -20.0, 30.0, -40.0, 50.0, 45.0), abs=1e-4)
    assert clamped_targets_deg([0.0] * 6)[5] == pytest.approx(-10.0)  # the gripper's 0 is closed, -10°
    for bad in ([0.0] * 5, [0.0, 0.0, 0.0, 0.0, 0.0, math.nan]):
        with pytest.raises(ValueError, match="expected 6 finite numbers"):
            clamped_targets_deg(bad)


def test_the_observations_spaces_hold_what_each_obs_type_observes():
    names = CUBE_TO_BOX.object_state_names
    assert set(observation_space("state", SMALL, names).spaces) == {"agent_pos", "environment_state"}
    assert set(observation_space("pixels_agent_pos", SMALL, names).spaces) == {"agent_pos", "pixels"}
    every = observation_space("all", SMALL, names)
    assert set(every.spaces) == {"agent_pos", "environment_state", "pixels"}
    assert {name: space.shape for name, space in every["pixels"].spaces.items()} == {"front": (48, 64, 3),
                                                                                     "wrist": (48, 64, 3)}
    angles = agent_pos_space()
    assert angles.low[0] == pytest.approx(-110.0 - JOINT_OVERSHOOT_DEG, abs=1e-3)
    objects = environment_state_space(names)
    assert objects.high.tolist() == [1.0] * 10 and objects.shape == (10,)  # metres within 1 m; a quaternion's ±1


def test_reward_and_the_end_come_from_the_tasks_success():
    assert step_outcome(CUBE_TO_BOX, True) == (1.0, True)
    assert step_outcome(CUBE_TO_BOX, False) == (0.0, False)


@pytest.mark.parametrize("options, message", [
    ({"body": "gazebo"}, "body='gazebo' is not one of: 'pybullet', 'mujoco'"),
    ({"body": "real"}, "body='real' is not one of: 'pybullet', 'mujoco'"),
    ({"obs_type": "pixels"}, "obs_type='pixels' is not one of: 'state', 'pixels_agent_pos', 'all'"),
    ({"looks": "shiny"}, "looks='shiny' is not one of: 'fixed', 'varied'"),
    ({"physics": "heavy"}, "physics: unknown physics 'heavy'; use fixed, varied, or a JSON file of ranges"),
    ({"backdrop": "front=/no/table.png"}, "backdrop: /no/table.png does not exist: give a photo of the workspace"),
    ({"render_mode": "ansi"}, "render_mode='ansi' is not one of: 'rgb_array'"),
    ({"camera_size": (63, 48)}, "camera_size=(63, 48) is not (width, height) in even pixels from 16 to 4096"),
    ({"camera_size": "320x240"}, "camera_size='320x240' is not (width, height)"),
])
@pytest.mark.filterwarnings("ignore:.*not in the possible render_modes")  # Gymnasium's own, before ours
def test_bad_arguments_are_refused_in_one_line_before_a_simulator_loads(options, message):
    with pytest.raises(ValueError) as refused:
        gymnasium.make(ENV_ID, **options)
    assert message in str(refused.value) and "\n" not in str(refused.value)


def test_a_camera_size_is_width_then_height():
    assert check_camera_size((320, 240)) == (320, 240) and check_camera_size([16, 4096]) == (16, 4096)


def test_the_environment_is_registered_with_so101_evals_time_limit_and_frame_rate():
    spec = gymnasium.spec(ENV_ID)
    assert spec.max_episode_steps == MAX_EPISODE_STEPS == 750  # 30 s at 25 frames a second
    assert CubeToBoxEnv.metadata == {"render_modes": ["rgb_array"], "render_fps": 25}
    env = make()
    try:
        assert env.get_wrapper_attr("_max_episode_steps") == 750
        assert env.unwrapped.task == env.unwrapped.task_description == CUBE_TO_BOX.instruction
    finally:
        env.close()


def test_the_policy_environment_installs_pyproject_tomls_own_pins_of_the_simulators():
    from so101.policy.environment import SIMULATION_REQUIREMENTS

    dependencies = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    for requirement in SIMULATION_REQUIREMENTS:
        name = requirement.split("=")[0].split(">")[0].split("<")[0]
        assert [dependency.replace(" ", "") for dependency in dependencies if dependency.startswith(name)] == [
            requirement], requirement


# -- Gymnasium's conformance check, determinism, layouts -----------------------------------------------------------

@pytest.mark.parametrize("obs_type", OBS_TYPES)
@pytest.mark.parametrize("body", BODIES)
def test_gymnasiums_check_env_passes(body, obs_type):
    env = make(body, obs_type=obs_type)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # every other warning of the checker fails the test
            # The checker's advice for RL's sake; the actions are LeRobot's units on purpose.
            warnings.filterwarnings("ignore", message=".*symmetric and normalized space")
            check_env(env.unwrapped)
    finally:
        env.close()


def expert_steps(env, policy, seed, steps):
    observation, _ = env.reset(seed=seed)
    seen = [observation]
    for _ in range(steps):
        observation, *_ = env.step(policy(env))
        seen.append(observation)
    return seen


@pytest.mark.parametrize("body", BODIES)
def test_a_seeded_reset_and_the_same_actions_give_the_same_episode_again_and_in_another_environment(body):
    # Varied physics: the layout's seed draws it again, the cube rebuilt to its size between episodes.
    first, second = make(body, obs_type="all", physics="varied"), make(body, obs_type="all", physics="varied")
    try:
        with ExpertPolicy() as policy:
            # 100 frames: down to the cube and the jaws closing on it (contacts, the cube moved).
            once = expert_steps(first, policy, 7, 100)
            expert_steps(first, policy, 8, 30)  # another episode between
            again = expert_steps(first, policy, 7, 100)
            elsewhere = expert_steps(second, policy, 7, 100)
    finally:
        first.close()
        second.close()
    assert np.abs(once[-1]["agent_pos"] - once[0]["agent_pos"]).max() > 10  # the arm went somewhere
    for one, other in ((once, again), (once, elsewhere)):
        for a, b in zip(one, other):
            assert np.array_equal(a["agent_pos"], b["agent_pos"]) and np.array_equal(a["environment_state"], b["environment_state"])
            assert np.array_equal(a["pixels"]["front"], b["pixels"]["front"])
            assert np.array_equal(a["pixels"]["wrist"], b["pixels"]["wrist"])


@pytest.mark.parametrize("body", BODIES)
def test_reset_seed_n_lays_out_the_tasks_layout_n_with_the_arm_at_home(body):
    env = make(body)
    try:
        for seed in (0, 12, 1000):
            observation, info = env.reset(seed=seed)
            layout = CUBE_TO_BOX.layout(seed)
            seen = seen_in(observation["environment_state"])
            assert seen.cube_xyz_m == pytest.approx(layout.cube_xyz_m, abs=1e-6)
            assert seen.cube_yaw_rad == pytest.approx(layout.cube_yaw_rad, abs=1e-6)
            assert seen.box_xyz_m == pytest.approx(layout.box_xyz_m, abs=1e-6)
            assert observation["agent_pos"] == pytest.approx(to_lerobot(HOME_POSE_DEG), abs=1e-3)
            assert info == {"is_success": False, "seed": seed, "frame": 0}
        # Without a seed: a layout drawn from the environment's generator, seeded by the reset before.
        drawn = [env.reset()[1]["seed"] for _ in range(2)]
        env.reset(seed=1000)
        assert [env.reset()[1]["seed"] for _ in range(2)] == drawn and drawn[0] != drawn[1]
    finally:
        env.close()


def test_an_action_beyond_the_limits_is_held_to_them_and_the_arm_goes_there():
    env = make("mujoco")
    try:
        env.reset(seed=0)
        action = np.array([500.0, 0.0, 0.0, 0.0, 0.0, 50.0], dtype=np.float32)
        for _ in range(50):  # 2 s: 110° at the course's 3 rad/s and the servo's pace
            observation, reward, terminated, truncated, info = env.step(action)
        assert observation["agent_pos"][0] == pytest.approx(ACTUATED_JOINTS[0].upper_deg, abs=2.0)
        assert (reward, terminated, truncated, info["frame"]) == (0.0, False, False, 50)
        with pytest.raises(ValueError, match="expected 6 finite numbers"):
            env.step(np.full(6, np.nan, dtype=np.float32))
    finally:
        env.close()


def test_render_gives_the_front_picture_and_the_varied_looks_change_it_by_seed():
    fixed, varied = make("pybullet", looks="fixed"), make("pybullet", looks="varied")
    try:
        pictures = {}
        for name, env in (("fixed", fixed), ("varied", varied)):
            for seed in (1, 2):
                env.reset(seed=seed)
                pictures[name, seed] = env.render()
        assert pictures["fixed", 1].shape == (48, 64, 3) and pictures["fixed", 1].dtype == np.uint8
        assert pictures["fixed", 1].std() > 5  # a scene, not a blank
        assert not np.array_equal(pictures["varied", 1], pictures["varied", 2])
        assert not np.array_equal(pictures["fixed", 1], pictures["varied", 1])
    finally:
        fixed.close()
        varied.close()


# -- the expert through the API ------------------------------------------------------------------------------------

@pytest.mark.parametrize("body", BODIES)
def test_the_expert_through_the_gymnasium_api_puts_the_cube_in_the_box(body):
    env = make(body)
    try:
        with ExpertPolicy() as policy:
            outcomes = [run_episode(env, policy, seed, index) for index, seed in enumerate((0, 1, 2))]
    finally:
        env.close()
    assert [outcome.success for outcome in outcomes] == [True, True, True]
    assert all(100 < outcome.frames < MAX_EPISODE_STEPS and outcome.seconds == (outcome.frames - 1) / 25
               for outcome in outcomes)


def test_the_expert_asks_for_a_reset_and_for_this_environment():
    with ExpertPolicy() as policy:
        env = make()
        try:
            with pytest.raises(gymnasium.error.ResetNeeded):
                policy(env)
        finally:
            env.close()
        other = gymnasium.make("CartPole-v1")
        with pytest.raises(TypeError, match="the expert acts on so101/CubeToBox-v0, not on CartPoleEnv"):
            policy(other)


# -- vector environments, EnvHub -------------------------------------------------------------------------------------

def test_an_async_vector_of_two_runs_two_episodes_at_once():
    vector = gymnasium.make_vec(ENV_ID, num_envs=2, vectorization_mode="async")
    try:
        observation, info = vector.reset(seed=[1000, 1001])
        assert observation["agent_pos"].shape == (2, 6) and info["seed"].tolist() == [1000, 1001]
        layouts = [CUBE_TO_BOX.layout(seed).cube_xyz_m for seed in (1000, 1001)]
        assert observation["environment_state"][:, :3] == pytest.approx(np.array(layouts), abs=1e-6)
        for _ in range(5):
            observation, reward, terminated, truncated, info = vector.step(np.tile(to_lerobot(HOME_POSE_DEG), (2, 1)))
        assert reward.tolist() == [0.0, 0.0] and info["frame"].tolist() == [5, 5]
    finally:
        vector.close()


def test_envhubs_make_env_gives_lerobot_a_vector_whose_final_info_says_success():
    from so101.gym.env import make_env

    envs = make_env(n_envs=2, use_async_envs=False, camera_size=SMALL)
    vector = envs["so101_cube_to_box"][0]
    try:
        assert vector.metadata["autoreset_mode"] == gymnasium.vector.AutoresetMode.SAME_STEP
        vector.reset(seed=[0, 1])
        with ExpertPolicy() as first, ExpertPolicy() as second:
            ended: dict[int, bool] = {}
            for _ in range(MAX_EPISODE_STEPS):
                actions = np.stack([policy(env) for policy, env in zip((first, second), vector.envs)])
                _, reward, terminated, truncated, info = vector.step(actions)
                # As LeRobot's rollout reads it: a finished episode's success in final_info.
                for index in np.flatnonzero(terminated | truncated):
                    ended.setdefault(int(index), bool(info["final_info"]["is_success"][index]))
                if len(ended) == 2:
                    break
        assert ended == {0: True, 1: True}
    finally:
        vector.close()
    with pytest.raises(ValueError, match="n_envs=0 is not a whole number of environments >= 1"):
        make_env(n_envs=0)


# -- LeRobot's own code, in the policy environment -------------------------------------------------------------------

HUB_PROBE = """
import json, sys
from lerobot.envs.utils import _call_make_env, _import_hub_module, _normalize_hub_result
module = _import_hub_module(sys.argv[1], "local/so101")
envs = _normalize_hub_result(_call_make_env(module, n_envs=2, use_async_envs=True, cfg=None))
(suite, tasks), = envs.items()
observation, info = tasks[0].reset(seed=[1000, 1001])
print(json.dumps({"suite": suite, "vector": type(tasks[0]).__name__, "state": list(observation["agent_pos"].shape),
                  "seeds": info["seed"].tolist(), "max_steps": int(tasks[0].call("_max_episode_steps")[0])}))
tasks[0].close()
"""


def this_checkout_first() -> dict[str, str]:
    """The environment for LeRobot's own commands, as a user runs them: offline, and importing this checkout's so101
    (the policy environment's link names whichever checkout last made it)."""
    return {**os.environ, "HF_HUB_OFFLINE": "1", "PYTHONPATH": with_checkout(os.environ.get("PYTHONPATH"))}


@pytest.mark.slow
def test_lerobots_envhub_loader_loads_env_py_and_calls_its_make_env(policy_python):  # noqa: F811
    done = subprocess.run([str(policy_python), "-c", HUB_PROBE, str(ROOT / "so101" / "gym" / "env.py")],
                          capture_output=True, text=True, timeout=300, cwd="/", env=this_checkout_first())
    assert done.returncode == 0, done.stderr[-3000:]
    assert json.loads(done.stdout.strip().splitlines()[-1]) == {
        "suite": "so101_cube_to_box", "vector": "AsyncVectorEnv", "state": [2, 6], "seeds": [1000, 1001], "max_steps": 750}


@pytest.mark.slow
def test_lerobot_eval_scores_a_state_only_checkpoint_on_the_environment(policy_python, tmp_path):  # noqa: F811
    out = tmp_path / "eval"
    command = [str(policy_python.parent / "lerobot-eval"), f"--policy.path={TINY_POLICY}", "--env.type=so101_cube_to_box",
               "--env.discover_packages_path=so101.gym", "--env.episode_length=40", "--eval.n_episodes=2",
               "--eval.batch_size=1", "--policy.device=cpu", f"--output_dir={out}"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=600, cwd="/",
                          env=this_checkout_first())
    assert done.returncode == 0, done.stderr[-3000:]
    (task,) = json.loads((out / "eval_info.json").read_text())["per_task"]
    assert task["task_group"] == "so101_cube_to_box"
    metrics = task["metrics"]
    # The untrained checkpoint puts nothing in the box: two episodes, each 0 reward, no success.
    assert metrics["successes"] == [False, False] and metrics["sum_rewards"] == [0.0, 0.0]
    assert all((out / "videos" / "so101_cube_to_box_0" / f"eval_episode_{index}.mp4").stat().st_size > 0
               for index in range(2))


def test_importing_so101_gym_imports_no_lerobot_and_no_simulator():
    probe = "import sys, so101.gym; print(','.join(sorted({name.split('.')[0] for name in sys.modules})))"
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=ROOT, check=True)
    loaded = set(done.stdout.strip().split(","))
    assert not loaded & {"lerobot", "torch", "pybullet", "mujoco"} and "gymnasium" in loaded
    assert so101.gym.ENV_ID in gymnasium.registry
