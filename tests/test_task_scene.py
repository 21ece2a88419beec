"""The task's scene on both simulators, from one description: the same layout, a cube that can be held, a reset.

Each test runs on every simulated body of so101.bodies.registry (PyBullet and MuJoCo).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from so101 import assets
from so101.bodies.jaw_pads import INNER_FACE_SIGN, PAD_GEOM_NAMES, jaw_pads
from so101.bodies.registry import BODIES, SIMULATED_BODIES
from so101.kinematics import Kinematics
from so101.robot import HOME_POSE_DEG
from so101.tasks import CUBE_TO_BOX
from so101.tasks.cube_to_box import Layout
from so101.tasks.expert import CLOSED_DEG, GRASP_CLEARANCE_M, GRASP_TURN_RAD, OPEN_DEG
from so101.tasks.grasp import GRIPPER_LINK_INDEX, TopDownGrasp, top_down_rotation

pytestmark = pytest.mark.slow  # steps both simulators for seconds: not in the fast subset

STEP_S = 0.004


def make(body_name, **options):
    return BODIES[body_name].body_class()(mode="direct", time_step_s=STEP_S, renders=False, log=lambda line: None,
                                          task=CUBE_TO_BOX, **options)


def run_for(sim, seconds):
    sim.step(round(seconds / STEP_S))


@pytest.fixture(scope="module")
def grasp():
    with Kinematics() as kinematics:
        fixed_pad = jaw_pads(assets.mjcf_path())[0].grown()
        yield TopDownGrasp(kinematics, fixed_pad, CUBE_TO_BOX.cube.half_size_m, GRASP_CLEARANCE_M)


@pytest.mark.parametrize("body_name", SIMULATED_BODIES)
def test_the_same_seed_lays_the_same_scene_out_on_each_simulator_and_it_stays(body_name):
    for seed in (0, 1, 41):
        layout = CUBE_TO_BOX.layout(seed)
        with make(body_name, seed=seed) as sim:
            for when in ("at start", "after 1 s"):
                state = sim.scene.object_state()
                assert state.dtype == np.float32 and state.shape == (10,)
                assert np.allclose(state[0:3], layout.cube_xyz_m, atol=0.001), when
                assert np.allclose(state[3:7], layout.cube_quat_xyzw(), atol=0.002), when
                assert np.allclose(state[7:10], layout.box_xyz_m, atol=0.001), when
                assert not sim.scene.succeeded()
                run_for(sim, 1.0)


def grasp_and_lift(sim, layout: Layout, above_deg, down_deg, lifted_deg) -> None:
    """The expert's grasp in four moves, with time to settle: open above the cube, down, close, up."""
    sim.scene.lay_out(layout)
    for arm_deg, gripper_deg, seconds in ((above_deg, OPEN_DEG, 1.5), (down_deg, OPEN_DEG, 1.5),
                                          (down_deg, CLOSED_DEG, 1.0), (lifted_deg, CLOSED_DEG, 1.5)):
        sim.set_targets_deg([*arm_deg, gripper_deg])
        run_for(sim, seconds)


@pytest.mark.parametrize("body_name", SIMULATED_BODIES)
def test_a_cube_grasped_and_lifted_10_cm_stays_in_the_gripper_for_5_s(body_name, grasp):
    layout = Layout(0, (0.2, -0.05, CUBE_TO_BOX.cube.half_size_m), math.radians(20), (*CUBE_TO_BOX.box.xy_m, 0.0))
    cube = np.array(layout.cube_xyz_m)
    above = grasp.pose(cube + [0, 0, 0.06], layout.cube_yaw_rad)
    down = grasp.pose(cube, layout.cube_yaw_rad, seed_deg=above.arm_deg)
    assert above.exact and down.exact
    # Straight up by 10 cm; the gripper need not point straight down on the way (close to the base
    # it cannot: the wrist would pass its limit).
    tip_mm = np.array(grasp.kinematics.tip_mm(down.arm_deg))
    lifted = grasp.kinematics.solve(tip_mm + [0, 0, 100], seed_deg=down.arm_deg)
    assert lifted.reachable
    with make(body_name) as sim:
        grasp_and_lift(sim, layout, above.arm_deg, down.arm_deg, lifted.joints_deg)
        lifted_xyz = sim.scene.object_state()[0:3].copy()
        assert lifted_xyz[2] > cube[2] + 0.08, "the cube did not come up with the gripper"
        run_for(sim, 5.0)
        held_xyz = sim.scene.object_state()[0:3]
        gripper_deg = sim.joint_angles_deg()[-1]
    assert np.linalg.norm(held_xyz - lifted_xyz) < 0.003, f"the cube moved {held_xyz - lifted_xyz} m in the gripper"
    assert gripper_deg > 5.0, "the jaws closed on nothing"


def lifts_the_cube(body_name, grasp, off_m: float, turned_deg: float) -> bool:
    """The expert's grasp (its opening, its branch of the wrist's roll): open above the cube, down,
    close, up 8 cm: is the cube up? The grasp point `off_m` along the jaws' axis from the expert's
    (toward the moving jaw: +), the jaws `turned_deg` off the cube's faces."""
    layout = Layout(0, (0.2, -0.05, CUBE_TO_BOX.cube.half_size_m), math.radians(20), (*CUBE_TO_BOX.box.xy_m, 0.0))
    yaw_rad = layout.cube_yaw_rad + GRASP_TURN_RAD
    point = np.array(layout.cube_xyz_m) + off_m * top_down_rotation(yaw_rad)[:, 0]
    yaw_rad += math.radians(turned_deg)
    above = grasp.pose_at_yaw(point + [0, 0, 0.06], yaw_rad)
    down = grasp.pose_at_yaw(point, yaw_rad, seed_deg=above.arm_deg)
    lifted = grasp.kinematics.solve(np.array(grasp.kinematics.tip_mm(down.arm_deg)) + [0, 0, 80], seed_deg=down.arm_deg)
    assert above.exact and down.exact and lifted.reachable
    with make(body_name) as sim:
        grasp_and_lift(sim, layout, above.arm_deg, down.arm_deg, lifted.joints_deg)
        return bool(sim.scene.object_state()[2] > layout.cube_xyz_m[2] + 0.05)


@pytest.mark.parametrize("body_name", SIMULATED_BODIES)
def test_a_grasp_10_mm_off_either_way_or_turned_15_degrees_still_lifts_the_cube(body_name, grasp):
    # The expert's open jaws leave room about its grasp point (GRASP_CLEARANCE_M), so a policy that
    # learned it may miss by this much. Much farther, a jaw comes down on the cube.
    for off_m, turned_deg in ((-0.010, 0.0), (0.010, 0.0), (0.0, -15.0), (0.0, 15.0), (-0.010, -15.0), (0.010, 15.0)):
        assert lifts_the_cube(body_name, grasp, off_m, turned_deg), (off_m, turned_deg)
    assert not lifts_the_cube(body_name, grasp, 0.032, 0.0)
    assert not lifts_the_cube(body_name, grasp, -0.036, 0.0)


@pytest.mark.parametrize("body_name", SIMULATED_BODIES)
def test_reset_lays_the_next_scene_out_and_homes_the_arm_as_a_fresh_start_does(body_name):
    with make(body_name, seed=3) as sim, make(body_name, seed=4) as fresh:
        sim.set_targets_deg([30.0, -20.0, 40.0, 10.0, 0.0, 50.0])
        run_for(sim, 1.0)
        sim.reset_task(4)
        assert sim.scene.layout == CUBE_TO_BOX.layout(4)
        assert np.allclose(sim.joint_angles_deg(), HOME_POSE_DEG, atol=1e-6)
        assert np.allclose(sim.scene.object_state(), fresh.scene.object_state(), atol=1e-6)
        # Still, its goal home: it goes on as a body started with that seed does.
        run_for(sim, 0.5)
        run_for(fresh, 0.5)
        assert np.allclose(sim.joint_angles_deg(), fresh.joint_angles_deg(), atol=0.01)
        assert np.allclose(sim.scene.object_state(), fresh.scene.object_state(), atol=1e-4)


@pytest.mark.parametrize("body_name", SIMULATED_BODIES)
def test_without_a_task_there_is_no_scene_and_no_reset(body_name):
    with BODIES[body_name].body_class()(mode="direct", renders=False, log=lambda line: None) as sim:
        assert sim.scene is None
        with pytest.raises(ValueError, match="runs no task"):
            sim.reset_task(1)


def test_every_corner_of_where_a_cube_may_start_can_be_grasped_from_above(grasp):
    for x, y in CUBE_TO_BOX.sector.corners_xy_m():
        for yaw_deg in (-45.0, 0.0, 44.9):
            pose = grasp.pose((x, y, CUBE_TO_BOX.cube.half_size_m), math.radians(yaw_deg))
            assert pose.exact, (x, y, yaw_deg, pose)


def test_each_pads_inner_face_looks_at_the_other_pad():
    # INNER_FACE_SIGN, checked with the kinematics: the pads' x axes and their centres, with the jaw half open.
    pads = {pad.name: pad for pad in jaw_pads(assets.mjcf_path())}
    assert tuple(pads) == PAD_GEOM_NAMES
    import pybullet as p

    with Kinematics() as kinematics:
        client, robot = kinematics.client, kinematics.robot_id
        p.resetJointState(robot, 6, math.radians(26.4), physicsClientId=client)  # the MJCF's "parallel" angle
        centres, axes = {}, {}
        for name, link in (("fixed_jaw_pad", GRIPPER_LINK_INDEX), ("moving_jaw_pad", 6)):
            state = p.getLinkState(robot, link, computeForwardKinematics=True, physicsClientId=client)
            pad = pads[name]
            w, x, y, z = pad.quat_wxyz
            link_rotation = np.asarray(p.getMatrixFromQuaternion(state[5])).reshape(3, 3)
            pad_rotation = np.asarray(p.getMatrixFromQuaternion([x, y, z, w])).reshape(3, 3)
            centres[name] = np.asarray(state[4]) + link_rotation @ pad.pos_m
            axes[name] = link_rotation @ pad_rotation[:, 0]
    between = centres["moving_jaw_pad"] - centres["fixed_jaw_pad"]
    assert np.dot(axes["fixed_jaw_pad"] * INNER_FACE_SIGN["fixed_jaw_pad"], between) > 0.99 * np.linalg.norm(between)
    assert np.dot(axes["moving_jaw_pad"] * INNER_FACE_SIGN["moving_jaw_pad"], -between) > 0.99 * np.linalg.norm(between)


def test_the_wrist_camera_sees_the_cube_between_the_jaws_alike_on_both_simulators(grasp):
    from so101.bodies.camera import WRIST_CAMERA

    layout = Layout(0, (0.2, -0.05, CUBE_TO_BOX.cube.half_size_m), 0.3, (*CUBE_TO_BOX.box.xy_m, 0.0))
    above = grasp.pose(np.array(layout.cube_xyz_m) + [0, 0, 0.05], layout.cube_yaw_rad)
    centres = {}
    for body_name in SIMULATED_BODIES:
        sim = BODIES[body_name].body_class()(mode="direct", log=lambda line: None, task=CUBE_TO_BOX)
        with sim:
            sim.scene.lay_out(layout)
            sim.show_pose_deg([*above.arm_deg, 35.0])
            rgb = sim.render_rgb(160, 120, WRIST_CAMERA).astype(int)
        red = (rgb[..., 0] > rgb[..., 1] + 60) & (rgb[..., 0] > rgb[..., 2] + 60)  # the cube: red, lit or shaded
        assert red.sum() > 30, f"{body_name}: the cube is not in the wrist camera's picture"
        rows, columns = np.nonzero(red)
        centres[body_name] = (rows.mean(), columns.mean())
    (row_a, column_a), (row_b, column_b) = centres.values()
    assert abs(row_a - row_b) < 6 and abs(column_a - column_b) < 6, centres  # pixels, of 160x120


def test_the_wrist_camera_is_a_tasks():
    from so101.bodies.camera import WRIST_CAMERA

    for body_name in SIMULATED_BODIES:
        with BODIES[body_name].body_class()(mode="direct", log=lambda line: None) as sim:
            with pytest.raises(ValueError, match="the wrist camera is a task's"):
                sim.render_rgb(64, 48, WRIST_CAMERA)


def test_light_pictures_leave_out_shadows_and_multisampling_and_still_show_the_scene():
    from so101.bodies.mujoco_sim import SO101MuJoCo  # first: it chooses MuJoCo's OpenGL back end

    import mujoco

    with SO101MuJoCo(mode="direct", log=lambda line: None, task=CUBE_TO_BOX, light_pictures=True) as light, \
            SO101MuJoCo(mode="direct", log=lambda line: None, task=CUBE_TO_BOX) as full:
        pictures = {name: sim.render_rgb(160, 120).astype(int) for name, sim in (("light", light), ("full", full))}
        flags = light._renderer.scene.flags
        assert not flags[mujoco.mjtRndFlag.mjRND_SHADOW] and not flags[mujoco.mjtRndFlag.mjRND_REFLECTION]
        assert light.model.vis.quality.offsamples == 0 and full.model.vis.quality.offsamples > 0
        assert full._renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW]
    for name, rgb in pictures.items():
        red = (rgb[..., 0] > rgb[..., 1] + 60) & (rgb[..., 0] > rgb[..., 2] + 60)
        assert red.sum() > 10, f"{name}: no cube in the picture"
    assert np.abs(pictures["light"] - pictures["full"]).mean() > 1.0  # the shadows are gone
