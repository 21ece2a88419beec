"""The arm moves exactly as the course's arm moves.

The reference is written from the course's own calls (step C's `setup_pybullet` and
`set_all_joint_positions`) in plain PyBullet, on its own client, with the node's 4 ms
step; the simulator must match it at every step. The course leaves the gripper out of
its loop (README, difference 8): here the same call drives it too, as the node does.
"""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pybullet_data
import pytest

from so101 import assets
from so101.runtime.dataflow import TICK_PERIOD_S
from so101.bodies.pybullet_sim import SO101Sim

pytestmark = pytest.mark.slow  # steps PyBullet through the course's motions: not in the fast subset

TOLERANCE_DEG = 0.01
STEPS_PER_COMMAND = 250  # 1 s: every move below ends and settles well within it
COURSE_JOINTS = [0, 1, 2, 3, 4, 6]  # step C's ARM_JOINTS, and the gripper


class CourseArm:
    """Course step C's PyBullet calls, verbatim but for the client id and the step."""

    def __init__(self):
        self.client = p.connect(p.DIRECT)
        cid = self.client
        p.setAdditionalSearchPath(pybullet_data.getDataPath(), physicsClientId=cid)
        p.setGravity(0, 0, -9.81, physicsClientId=cid)
        p.setTimeStep(TICK_PERIOD_S, physicsClientId=cid)
        p.loadURDF("plane.urdf", physicsClientId=cid)
        self.robot_id = p.loadURDF(str(assets.urdf_path()), useFixedBase=True, physicsClientId=cid)
        for joint_idx in range(p.getNumJoints(self.robot_id, physicsClientId=cid)):
            p.changeDynamics(self.robot_id, joint_idx, linearDamping=0.2, angularDamping=0.2, physicsClientId=cid)

    def tick(self, angles_deg) -> list[float]:
        for joint_idx, angle in zip(COURSE_JOINTS, angles_deg):
            p.setJointMotorControl2(
                bodyUniqueId=self.robot_id, jointIndex=joint_idx, controlMode=p.POSITION_CONTROL,
                targetPosition=angle * math.pi / 180.0, maxVelocity=3.0, physicsClientId=self.client,
            )
        p.stepSimulation(physicsClientId=self.client)
        states = p.getJointStates(self.robot_id, COURSE_JOINTS, physicsClientId=self.client)
        return [state[0] * 180.0 / math.pi for state in states]

    def close(self):
        p.disconnect(physicsClientId=self.client)


def home_with(position: int, angle_deg: float) -> list[float]:
    targets = [0.0] * 6
    targets[position] = angle_deg
    return targets


SCENARIOS = {
    **{f"{joint} 90": [home_with(joint, 90.0)] for joint in range(5)},
    "gripper to 50": [home_with(5, 50.0)],
    "batch -30 45 -60 30 0, then home": [[-30.0, 45.0, -60.0, 30.0, 0.0, 0.0], [0.0] * 6],
}


@pytest.mark.parametrize("commands", SCENARIOS.values(), ids=SCENARIOS.keys())
def test_the_simulator_follows_the_courses_calls_step_by_step(commands):
    course = CourseArm()
    sim = SO101Sim(mode="direct", time_step_s=TICK_PERIOD_S, log=lambda message: None)
    try:
        worst_deg = 0.0
        moved_deg = 0.0
        for targets_deg in commands:
            sim.set_targets_deg(targets_deg)
            for step in range(STEPS_PER_COMMAND):
                expected = np.array(course.tick(targets_deg))
                sim.step()
                actual = sim.joint_angles_deg()
                error = np.max(np.abs(actual - expected))
                assert error <= TOLERANCE_DEG, f"{targets_deg} step {step}: {actual} vs the course's {expected}"
                worst_deg = max(worst_deg, error)
                moved_deg = max(moved_deg, float(np.max(np.abs(expected))))
        assert moved_deg > 40  # the comparison covered a real move, not an arm at rest
    finally:
        sim.close()
        course.close()


def test_a_joint_moves_on_the_first_step_after_a_command():
    # maxVelocity caps the motor's velocity target: 4° away, the first 4 ms step covers
    # about 0.4°, the gain's share (0.1 · error / step), below the 3 rad/s cap (0.69°).
    sim = SO101Sim(mode="direct", time_step_s=TICK_PERIOD_S, log=lambda message: None)
    try:
        sim.step(50)
        before = sim.joint_angles_deg()[0]
        sim.set_targets_deg(home_with(0, 4.0))
        sim.step()
        assert sim.joint_angles_deg()[0] - before == pytest.approx(0.4, abs=0.05)
    finally:
        sim.close()


def contact_points(client: int, robot_id: int) -> list[tuple]:
    """The arm's contacts with anything: (link, other body, other link, position on the arm)."""
    return sorted(
        (point[3], point[2], point[4], *point[5]) for point in p.getContactPoints(bodyA=robot_id, physicsClientId=client)
    )


def test_leaving_out_the_renderer_and_the_file_cache_changes_no_physics():
    # The node's memory savings (renders=False unloads PyBullet's CPU renderer and its file
    # cache before loading) against the course's plain loading, through ground contact:
    # shoulder_lift at 90° presses the gripper into the floor, then the pan sweeps it along.
    course = CourseArm()
    sim = SO101Sim(mode="direct", time_step_s=TICK_PERIOD_S, log=lambda message: None, renders=False)
    try:
        contacts_seen = 0
        for targets_deg in ([0.0, 90.0, 0.0, 0.0, 0.0, 30.0], [60.0, 90.0, 0.0, 0.0, 0.0, 30.0]):
            sim.set_targets_deg(targets_deg)
            for step in range(STEPS_PER_COMMAND):
                expected = np.array(course.tick(targets_deg))
                sim.step()
                assert np.max(np.abs(sim.joint_angles_deg() - expected)) <= 1e-9, f"{targets_deg} step {step}"
                sim_contacts = contact_points(sim.client, sim.robot_id)
                course_contacts = contact_points(course.client, course.robot_id)
                assert [c[:3] for c in sim_contacts] == [c[:3] for c in course_contacts], f"step {step}"
                assert np.allclose([c[3:] for c in sim_contacts], [c[3:] for c in course_contacts], rtol=0, atol=1e-9)
                contacts_seen += bool(sim_contacts)
        assert contacts_seen > 100  # the comparison covered the arm on the ground, not only in the air
    finally:
        sim.close()
        course.close()


def test_a_simulator_without_its_renderer_refuses_pictures():
    sim = SO101Sim(mode="direct", log=lambda message: None, renders=False)
    try:
        with pytest.raises(RuntimeError, match=r"made without its renderer \(renders=False\): no pictures"):
            sim.render_rgb(32, 32)
    finally:
        sim.close()
