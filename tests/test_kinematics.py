"""so101.kinematics (FK and IK of the gripper tip) and `so101 reach` (the accuracy check).

The FK oracle is independent of PyBullet: the URDF's joint origins and axes, chained by hand
with numpy (a URDF joint is: translate by origin xyz, rotate by origin rpy = Rz·Ry·Rx, then
rotate about its axis by the joint angle).
"""

from __future__ import annotations

import json
import math
import random
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from so101.assets import ModelFilesError
from so101.cli.main import main
from so101.kinematics import REACH_TOLERANCE_MM, Kinematics, Reach
from so101.robot import ARM_JOINTS, HOME_POSE_DEG, NUM_ARM_JOINTS
from tests.helpers.dataflow import run_so101

# The tip at home, from the URDF's numbers (see urdf_tip_mm): the upper arm stands up, the
# forearm and the gripper reach forward level, 391 mm out and 226 mm up.
HOME_TIP_MM = (391.36, -0.01, 226.47)


@pytest.fixture(scope="module")
def kin():
    with Kinematics() as kinematics:
        yield kinematics


# -- the independent oracle -----------------------------------------------------------------------


def _floats(text: str) -> np.ndarray:
    return np.array([float(value) for value in text.split()])


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    x, y, z = axis / np.linalg.norm(axis)
    c, s, t = math.cos(angle), math.sin(angle), 1 - math.cos(angle)
    return np.array([
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ])


def urdf_tip_mm(urdf_path, arm_deg) -> np.ndarray:
    """The tip (gripper_frame_link's origin) in base_link's frame, chained from the URDF text."""
    root = ET.parse(urdf_path).getroot()
    joint_of_child = {joint.find("child").get("link"): joint for joint in root.findall("joint")}
    chain, link = [], "gripper_frame_link"
    while link in joint_of_child:
        chain.append(joint_of_child[link])
        link = joint_of_child[link].find("parent").get("link")
    assert link == "base_link"
    angles = {joint.name: math.radians(angle) for joint, angle in zip(ARM_JOINTS, arm_deg)}
    transform = np.eye(4)
    for joint in reversed(chain):
        origin = joint.find("origin")
        roll, pitch, yaw = _floats(origin.get("rpy"))
        step = np.eye(4)
        step[:3, 3] = _floats(origin.get("xyz"))
        step[:3, :3] = (
            _rotation(np.array([0, 0, 1.0]), yaw) @ _rotation(np.array([0, 1.0, 0]), pitch)
            @ _rotation(np.array([1.0, 0, 0]), roll)
        )
        if joint.get("type") == "revolute":
            turn = np.eye(4)
            turn[:3, :3] = _rotation(_floats(joint.find("axis").get("xyz")), angles[joint.get("name")])
            step = step @ turn
        transform = transform @ step
    return transform[:3, 3] * 1000.0


def random_poses(count: int, seed: int) -> list[tuple[float, ...]]:
    draw = random.Random(seed)
    return [tuple(draw.uniform(joint.lower_deg, joint.upper_deg) for joint in ARM_JOINTS) for _ in range(count)]


def within_limits(arm_deg) -> bool:
    return all(joint.lower_deg - 1e-6 <= angle <= joint.upper_deg + 1e-6 for joint, angle in zip(ARM_JOINTS, arm_deg))


# -- forward kinematics -----------------------------------------------------------------------------


def test_the_home_tip_is_where_the_urdf_puts_it(kin, model_dir):
    from so101.assets import URDF_NAME

    by_hand = urdf_tip_mm(model_dir / URDF_NAME, [0.0] * NUM_ARM_JOINTS)
    assert np.allclose(by_hand, HOME_TIP_MM, atol=0.05)
    assert np.allclose(kin.tip_mm(HOME_POSE_DEG[:NUM_ARM_JOINTS]), by_hand, atol=1.0)


def test_fk_agrees_with_the_urdf_chain_in_any_pose(kin, model_dir):
    from so101.assets import URDF_NAME

    for pose in random_poses(10, seed=4):
        assert np.allclose(kin.tip_mm(pose), urdf_tip_mm(model_dir / URDF_NAME, pose), atol=0.01), pose


def test_the_base_frame_is_x_forward_y_left_z_up(kin):
    home = np.array(kin.tip_mm([0, 0, 0, 0, 0]))
    assert home[0] > 300 and abs(home[1]) < 1  # forward, on the centre line
    pan_left = np.array(kin.tip_mm([-30, 0, 0, 0, 0]))  # a positive shoulder_pan turns right
    assert pan_left[1] > 150 and abs(pan_left[2] - home[2]) < 1
    raised = np.array(kin.tip_mm([0, -30, 0, 0, 0]))  # a positive shoulder_lift lowers the arm
    assert raised[2] > home[2] + 100
    # The gripper's own angle does not move the tip; wrist_roll only a little (it is 7.9 mm off the axis).
    assert np.linalg.norm(np.array(kin.tip_mm([0, 0, 0, 0, 90])) - home) < 12


# -- inverse kinematics -----------------------------------------------------------------------------


def test_solve_finds_the_tip_of_random_poses_within_a_millimetre_inside_the_limits(kin):
    for pose in random_poses(20, seed=7):
        target = kin.tip_mm(pose)
        reach = kin.solve(target)
        assert isinstance(reach, Reach) and reach.reachable, (pose, reach)
        assert reach.error_mm < REACH_TOLERANCE_MM
        assert len(reach.joints_deg) == NUM_ARM_JOINTS and within_limits(reach.joints_deg), reach
        # tip_mm and error_mm say what the joints do: FK of the answer, and its distance from the target.
        assert np.allclose(kin.tip_mm(reach.joints_deg), reach.tip_mm, atol=1e-6)
        assert math.isclose(math.dist(reach.tip_mm, target), reach.error_mm, abs_tol=1e-6)
        # Where the drawn pose shows a way from home clear of the floor, the answer takes one too.
        if kin.path_clear(HOME_POSE_DEG[:NUM_ARM_JOINTS], pose):
            assert kin.path_clear(HOME_POSE_DEG[:NUM_ARM_JOINTS], reach.joints_deg), (pose, reach)


def test_a_point_in_front_of_the_arm_is_reachable(kin):
    reach = kin.solve([200, 0, 150])
    assert reach.reachable and reach.error_mm < 0.1
    assert within_limits(reach.joints_deg)


def test_a_small_step_from_the_current_pose_stays_near_it(kin):
    # The seed is tried first: jogging the tip 5 mm moves no joint far.
    pose = (10.0, -20.0, 30.0, 10.0, 0.0)
    x, y, z = kin.tip_mm(pose)
    reach = kin.solve([x + 5, y, z - 5], seed_deg=pose)
    assert reach.reachable
    assert max(abs(new - old) for new, old in zip(reach.joints_deg, pose)) < 5


def test_of_the_exact_answers_solve_takes_one_the_arm_can_move_to_without_meeting_the_floor(kin, make_sim):
    # A point above and to the right of the base. Its first exact answer from home folds the
    # arm forward and down, and on the way the simulated gripper meets the floor and the arm
    # jams 520 mm away; solve passes it over for one whose way is clear.
    from so101.cli import reach as cmd_reach

    target = (59.64, -102.27, 170.73)
    home = HOME_POSE_DEG[:NUM_ARM_JOINTS]
    reach = kin.solve(target, seed_deg=home)
    assert reach.reachable and kin.path_clear(home, reach.joints_deg)
    sim = make_sim(time_step_s=0.004, renders=False)
    cmd_reach.settle(sim, reach.joints_deg + (0.0,))
    assert math.dist(cmd_reach.sim_tip_mm(sim), target) < cmd_reach.GOAL_MM
    # The answer it passed over, for the record: exact, but its way is not clear.
    folded = (-97.73, 86.15, 82.02, 55.68, 123.61)
    assert math.dist(kin.tip_mm(folded), target) < 0.1 and not kin.path_clear(home, folded)


def test_a_far_point_is_out_of_reach_and_the_nearest_point_is_at_arms_length(kin):
    reach = kin.solve([1000, 0, 0])
    assert not reach.reachable and reach.error_mm > 400
    assert 300 < math.dist(reach.tip_mm, (0, 0, 0)) < 500
    assert math.isclose(math.dist(reach.tip_mm, (1000, 0, 0)), reach.error_mm, abs_tol=1e-6)
    assert within_limits(reach.joints_deg)


@pytest.mark.parametrize("target", [
    [float("nan"), 0, 100], [200, float("inf"), 100], [200, 0], [200, 0, 100, 1], "200 0 100", None, ["a", 0, 0],
])
def test_a_bad_target_is_a_one_line_value_error(kin, target):
    with pytest.raises(ValueError) as raised:
        kin.solve(target)
    assert "\n" not in str(raised.value) and "x y z" in str(raised.value)


@pytest.mark.parametrize("angles", [[0, 0, 0, 0], [0, 0, 0, 0, 0, 0], [0, float("nan"), 0, 0, 0], [0, 0, 0, 0, -float("inf")]])
def test_bad_angles_are_a_one_line_value_error(kin, angles):
    with pytest.raises(ValueError, match="5 finite arm joint angles"):
        kin.tip_mm(angles)
    with pytest.raises(ValueError, match="5 finite arm joint angles"):
        kin.solve([200, 0, 150], seed_deg=angles)


def test_a_missing_model_raises_model_files_error(tmp_path):
    with pytest.raises(ModelFilesError, match="so101 assets"):
        Kinematics(assets_dir=tmp_path)


def test_close_is_safe_twice_and_a_closed_one_refuses():
    kinematics = Kinematics()
    kinematics.close()
    kinematics.close()
    with pytest.raises(RuntimeError, match="closed"):
        kinematics.tip_mm([0, 0, 0, 0, 0])


def test_importing_the_module_does_not_import_pybullet():
    code = "import sys, so101.kinematics; print('pybullet' in sys.modules)"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "False"


# -- so101 reach ------------------------------------------------------------------------------------


def test_a_target_reached_after_a_reset_ends_where_a_fresh_simulator_does(kin, make_sim):
    # `so101 reach` reuses one simulator, reset to home before each target: faithful only if
    # that is the state a new one (as the node has) starts in.
    from so101.cli import reach as cmd_reach

    pose, target = cmd_reach.draw_targets(kin, 1, seed=3).pairs[0]
    goal = kin.solve(target).joints_deg + (0.0,)
    reused = make_sim(time_step_s=0.004, renders=False)
    cmd_reach.settle(reused, (20.0, -30.0, 40.0, 10.0, 50.0, 10.0))  # somewhere else first
    cmd_reach.reset_home(reused)
    steps, still = cmd_reach.settle(reused, goal)
    fresh = make_sim(time_step_s=0.004, renders=False)
    fresh.set_targets_deg(goal)
    fresh.step(steps)
    assert still
    assert np.array_equal(reused.joint_angles_deg(), fresh.joint_angles_deg())
    assert math.dist(cmd_reach.sim_tip_mm(fresh), target) < cmd_reach.GOAL_MM


def test_so101_reach_prints_the_table_with_every_settled_error_under_5_mm(tmp_path):
    out = tmp_path / "reach.json"
    result = run_so101("reach", "--points", "10", "--out", str(out))
    assert result.returncode == 0, result.stdout + result.stderr
    rows = {line.split()[0] + (" " + line.split()[1] if line.startswith("settled tip") else ""): line
            for line in result.stdout.splitlines() if line.strip()}
    ik_p50, ik_p99, ik_max = (float(value) for value in rows["IK"].split()[1:])
    settled_p50, settled_p99, settled_max = (float(value) for value in rows["settled tip"].split()[2:])
    assert ik_max < REACH_TOLERANCE_MM
    assert settled_p50 <= settled_p99 <= settled_max < 5.0
    assert "out of reach for IK (more than 1 mm off): 0 of 10" in result.stdout
    assert "goal, every target within 5 mm after settling: met" in result.stdout
    figures = json.loads(out.read_text())
    assert figures["points"] == len(figures["targets"]) == 10
    assert figures["settled_error_mm"]["max"] == pytest.approx(settled_max, abs=0.01)
    assert all(target["target_mm"][2] >= 30 for target in figures["targets"])


@pytest.mark.parametrize("option", [["--points", "0"], ["--points", "2.5"], ["--seed", "x"]])
def test_so101_reach_refuses_bad_options_in_one_line(option, capsys):
    with pytest.raises(SystemExit) as exited:
        main(["reach", *option])
    assert exited.value.code == 2
    error = capsys.readouterr().err.strip().splitlines()[-1]
    assert error.startswith("so101 reach: error: argument") and option[1] in error
