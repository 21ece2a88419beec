"""The arm moves exactly as the course's arm moves.

The reference is written from the course's own calls (step C's `setup_pybullet` and
`set_all_joint_positions`) in plain PyBullet, on its own client, with the node's 4 ms
step; the simulator must match it at every step. The course leaves the gripper out of
its loop (docs/differences.md, difference 8): here the same call drives it too, as the node does.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pybullet as p
import pybullet_data
import pytest

from so101 import assets
from so101.runtime.dataflow import TICK_PERIOD_S
from so101.bodies import pybullet_hulls
from so101.bodies.pybullet_sim import SO101Sim
from tests.helpers.course_motion import SCENARIOS, STEPS_PER_COMMAND, home_with

pytestmark = pytest.mark.slow  # steps PyBullet through the course's motions: not in the fast subset

TOLERANCE_DEG = 0.01
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
    # cache before loading; the hull files stand for the full collision meshes) against the
    # course's plain loading, through ground contact: shoulder_lift at 90° presses the
    # gripper into the floor, then the pan sweeps it along.
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


HULL_TOLERANCE_RAD = 1e-6
CONTACT_TOLERANCE_M = 1e-9
ON_THE_GROUND = [[0.0, 90.0, 0.0, 0.0, 0.0, 30.0], [60.0, 90.0, 0.0, 0.0, 0.0, 30.0]]
EXERCISE_2 = {"control_mode": "servo"}
# (SO101Sim options, commands, whether the arm touches the ground): the course's motions (at 90°
# the shoulder_lift and the elbow put the gripper on the floor), the arm pressed into the floor and
# swept along it, and exercise 2: the course's arm without its link damping, and the servo,
# swinging and on the ground.
HULL_SCENARIOS = {
    **{name: ({}, commands, name in ("1 90", "2 90")) for name, commands in SCENARIOS.items()},
    "on the ground, swept along": ({}, ON_THE_GROUND, True),
    "exercise 2: without link damping, 0 90": ({"link_damping": None}, SCENARIOS["0 90"], False),
    **{
        f"exercise 2: servo, zeta {zeta}, 0 90": ({**EXERCISE_2, "servo_damping_ratio": zeta}, SCENARIOS["0 90"], False)
        for zeta in (0.2, 0.7)
    },
    "exercise 2: servo, on the ground": (EXERCISE_2, ON_THE_GROUND, True),
}


@pytest.mark.parametrize("options, commands, touches_the_ground", HULL_SCENARIOS.values(), ids=HULL_SCENARIOS.keys())
def test_the_hull_files_move_the_arm_as_the_full_meshes_do(options, commands, touches_the_ground):
    # The simulator collides the hull files derived from the model (so101.bodies.pybullet_hulls);
    # the course's full meshes must give the same motion, step by step, and the same contacts.
    made = [
        SO101Sim(mode="direct", time_step_s=TICK_PERIOD_S, log=lambda message: None, renders=False,
                 hull_collisions=hulls, **options)
        for hulls in (False, True)
    ]
    full, hull = made
    try:
        assert Path(p.getCollisionShapeData(hull.robot_id, 3, physicsClientId=hull.client)[1][4].decode()).parent.name == (
            pybullet_hulls.HULLS_DIR_NAME
        )
        contact_steps = 0
        moved_rad = 0.0
        for targets_deg in commands:
            for sim in made:
                sim.set_targets_deg(targets_deg)
            for step in range(STEPS_PER_COMMAND):
                for sim in made:
                    sim.step()
                expected_rad = np.radians(full.joint_angles_deg())
                error_rad = np.max(np.abs(np.radians(hull.joint_angles_deg()) - expected_rad))
                assert error_rad <= HULL_TOLERANCE_RAD, f"{targets_deg} step {step}: {error_rad} rad"
                full_contacts = contact_points(full.client, full.robot_id)
                hull_contacts = contact_points(hull.client, hull.robot_id)
                assert [c[:3] for c in hull_contacts] == [c[:3] for c in full_contacts], f"{targets_deg} step {step}"
                assert np.allclose([c[3:] for c in hull_contacts], [c[3:] for c in full_contacts],
                                   rtol=0, atol=CONTACT_TOLERANCE_M), f"{targets_deg} step {step}"
                contact_steps += bool(full_contacts)
                moved_rad = max(moved_rad, float(np.max(np.abs(expected_rad))))
        assert moved_rad > math.radians(40)  # a real move, not an arm at rest
        # Where the arm goes down, the comparison covered it on the ground, not only in the air.
        assert (contact_steps > 100) if touches_the_ground else (contact_steps == 0)
    finally:
        for sim in made:
            sim.close()


def test_a_simulator_without_its_renderer_refuses_pictures():
    sim = SO101Sim(mode="direct", log=lambda message: None, renders=False)
    try:
        with pytest.raises(RuntimeError, match=r"made without its renderer \(renders=False\): no pictures"):
            sim.render_rgb(32, 32)
    finally:
        sim.close()
