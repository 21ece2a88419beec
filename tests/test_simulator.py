"""SO101Sim: the joint table, reaching targets, degrees at the boundary, instances apart."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ElementTree

import pybullet as p
import pytest

from so101 import assets
from so101.robot import ACTUATED_JOINTS, ARM_JOINTS, GRIPPER, JOINT_TABLE

pytestmark = pytest.mark.slow  # steps PyBullet until joints settle: not in the fast subset

REACH_TOLERANCE_DEG = 0.5
# At the course's 3 rad/s a 90° move takes 126 steps; the slowest measured here took 150.
REACH_STEP_BUDGET = 400


def urdf_joints() -> dict[str, ElementTree.Element]:
    root = ElementTree.parse(assets.urdf_path()).getroot()
    # Only the robot's own <joint> children: <transmission> blocks name joints too.
    return {joint.get("name"): joint for joint in root.findall("joint")}


def steps_to_reach(sim, joint_position: int, target_deg: float, budget: int) -> int | None:
    for count in range(1, budget + 1):
        sim.step()
        if abs(sim.joint_angles_deg()[joint_position] - target_deg) < REACH_TOLERANCE_DEG:
            return count
    return None


def test_joint_table_is_the_courses(shared_sim, course_joint_table):
    table = [(joint.index, joint.name, joint.type) for joint in shared_sim.joints]
    assert table == course_joint_table
    assert list(JOINT_TABLE) == course_joint_table


def test_joint_types_and_limits_equal_the_urdf(shared_sim):
    declared = urdf_joints()
    assert set(declared) == {joint.name for joint in shared_sim.joints}
    for joint in shared_sim.joints:
        element = declared[joint.name]
        assert element.get("type") == joint.type
        if joint.type == "revolute":
            limit = element.find("limit")
            assert joint.lower_rad == pytest.approx(float(limit.get("lower")), abs=1e-9)
            assert joint.upper_rad == pytest.approx(float(limit.get("upper")), abs=1e-9)
            assert joint.max_force == pytest.approx(float(limit.get("effort")))


def test_robot_constants_equal_the_urdf():
    declared = urdf_joints()
    urdf_types = {name: joint.get("type") for name, joint in declared.items()}
    assert {name: kind for _, name, kind in JOINT_TABLE} == urdf_types
    for joint in ACTUATED_JOINTS:
        limit = declared[joint.name].find("limit")
        assert joint.lower_deg == pytest.approx(math.degrees(float(limit.get("lower"))), abs=1e-9), joint.name
        assert joint.upper_deg == pytest.approx(math.degrees(float(limit.get("upper"))), abs=1e-9), joint.name
    assert [joint.index for joint in ACTUATED_JOINTS] == [0, 1, 2, 3, 4, 6]
    assert GRIPPER.name == "gripper"


# Targets measured to be reachable from home. The others are not: shoulder_lift
# above about +37° and elbow_flex above about +48° swing the arm down into the
# ground plane and stop there (measured: +45° ends at 37.5°, +60° at 48.2°), so
# shoulder_lift goes up (negative) and elbow_flex stays at +45°.
REACHABLE_TARGETS_DEG = {
    "shoulder_pan": 60.0,
    "shoulder_lift": -45.0,
    "elbow_flex": 45.0,
    "wrist_flex": -60.0,
    "wrist_roll": 90.0,
}


@pytest.mark.parametrize("position, joint", list(enumerate(ARM_JOINTS)), ids=[j.name for j in ARM_JOINTS])
def test_each_arm_joint_reaches_a_reachable_target(make_sim, position, joint):
    sim = make_sim()
    target_deg = REACHABLE_TARGETS_DEG[joint.name]
    targets = [0.0] * len(ACTUATED_JOINTS)
    targets[position] = target_deg
    sim.set_targets_deg(targets)
    assert steps_to_reach(sim, position, target_deg, REACH_STEP_BUDGET) is not None
    # And it stays there, with the other joints still at home.
    sim.step(240)
    angles = sim.joint_angles_deg()
    assert angles[position] == pytest.approx(target_deg, abs=REACH_TOLERANCE_DEG)
    others = [angle for i, angle in enumerate(angles) if i != position]
    assert all(abs(angle) < 1.0 for angle in others), angles


def test_degrees_cross_the_boundary_as_radians(make_sim):
    sim = make_sim()
    sim.set_targets_deg([30.0, 0, 0, 0, 0, 0])
    sim.step(240)
    radians = p.getJointState(sim.robot_id, 0, physicsClientId=sim.client)[0]
    assert radians == pytest.approx(0.5236, abs=0.002)
    # And back: a state PyBullet holds in radians reads in degrees.
    p.resetJointState(sim.robot_id, 3, -math.pi / 4, physicsClientId=sim.client)
    assert sim.joint_angles_deg()[3] == pytest.approx(-45.0, abs=1e-6)


def test_targets_read_back_in_degrees(make_sim):
    sim = make_sim()
    sim.set_targets_deg([10, -20, 30, -40, 50, 5])
    assert list(sim.targets_deg()) == pytest.approx([10, -20, 30, -40, 50, 5])


@pytest.mark.parametrize(
    "bad", [[0.0] * 5, [0.0] * 7, [0, 0, float("nan"), 0, 0, 0], [0, 0, 0, float("inf"), 0, 0]],
    ids=["five", "seven", "nan", "inf"],
)
def test_bad_targets_are_refused_and_keep_the_old_goal(make_sim, bad):
    sim = make_sim()
    sim.set_targets_deg([20, 0, 0, 0, 0, 0])
    with pytest.raises(ValueError, match="expected 6 finite angles in degrees"):
        sim.set_targets_deg(bad)
    assert sim.targets_deg()[0] == pytest.approx(20)


def test_two_simulators_in_one_process_do_not_disturb_each_other(make_sim):
    first, second = make_sim(), make_sim()
    assert first.client != second.client
    first.set_targets_deg([45, 0, 0, 0, 0, 0])
    second.set_targets_deg([-30, 0, 0, 0, 0, 0])
    for _ in range(300):
        first.step()
        second.step()
    assert first.joint_angles_deg()[0] == pytest.approx(45, abs=REACH_TOLERANCE_DEG)
    assert second.joint_angles_deg()[0] == pytest.approx(-30, abs=REACH_TOLERANCE_DEG)
    # Stepping one leaves the other's state and clock alone.
    held = second.joint_angles_deg().copy()
    first.set_targets_deg([-60, 0, 0, 0, 0, 0])
    first.step(300)
    assert list(second.joint_angles_deg()) == list(held)
    assert (first.steps, second.steps) == (600, 300)
    # Closing one leaves the other working.
    first.close()
    second.step(10)
    assert second.joint_angles_deg()[0] == pytest.approx(-30, abs=REACH_TOLERANCE_DEG)


def test_close_twice_is_safe(make_sim):
    sim = make_sim()
    client = sim.client
    sim.close()
    sim.close()
    assert sim.client is None
    assert not p.isConnected(physicsClientId=client)


def test_position_control_targets_persist_without_re_issuing(make_sim):
    # Evidence for docs/differences.md (difference 4): PyBullet keeps a POSITION_CONTROL target until told
    # otherwise, so a node only needs to send a target when it changes.
    sim = make_sim()
    cid = sim.client
    p.setJointMotorControl2(
        sim.robot_id, 0, p.POSITION_CONTROL, targetPosition=0.5, maxVelocity=3.0, force=10.0,
        physicsClientId=cid,
    )
    for _ in range(500):
        p.stepSimulation(physicsClientId=cid)
    assert p.getJointState(sim.robot_id, 0, physicsClientId=cid)[0] == pytest.approx(0.5, abs=0.002)


def test_position_mode_moves_at_the_courses_max_velocity_and_stops_on_each_new_goal(make_sim):
    sim = make_sim()
    for goal_deg in (90.0, -45.0):  # the second goal comes after the first has been reached and held
        sim.set_targets_deg([goal_deg, 0, 0, 0, 0, 0])
        speeds_rad_s = []
        for _ in range(REACH_STEP_BUDGET):
            sim.step()
            speeds_rad_s.append(abs(math.radians(sim.joint_velocities_deg_s()[0])))
        assert max(speeds_rad_s) <= 3.0 * 1.02  # maxVelocity=3.0 rad/s, as the course sets it
        assert max(speeds_rad_s) >= 3.0 * 0.9  # and it does move that fast on the way
        assert sim.joint_angles_deg()[0] == pytest.approx(goal_deg, abs=REACH_TOLERANCE_DEG)
