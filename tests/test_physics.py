"""Physics that varies by seed (so101.bodies.physics): drawn the same for the same seed, within its ranges,
its ranges files checked, its command path's delay, speed limit and calibration, and both simulators
applying the same physics for the same seed."""

from __future__ import annotations

import json
from dataclasses import asdict, fields

import numpy as np
import pytest

from so101.bodies.command_path import CommandPath
from so101.bodies.physics import (
    DEFAULT_RANGES, NOMINAL, PhysicsError, PhysicsRanges, centred, draw_physics, physics_for, physics_from_metadata, physics_metadata,
    physics_mode,
)
from so101.bodies.registry import BODIES, SIMULATED_BODIES
from so101.robot import HOME_POSE_DEG
from so101.runtime.dataflow import TICK_PERIOD_S
from so101.tasks import CUBE_TO_BOX


def test_the_same_seed_draws_the_same_physics_within_its_ranges_and_other_seeds_other_ones():
    assert draw_physics(7) == draw_physics(7) == physics_for("varied", 7)
    assert physics_for("fixed", 7) is None and physics_metadata("fixed", 7) == {"physics": "fixed"}
    drawn = [draw_physics(seed) for seed in range(200)]
    assert len({physics.calibration_offsets_deg for physics in drawn}) == 200
    for name in ("cube_size_m", "cube_mass_kg", "cube_friction", "servo_stiffness", "servo_damping", "command_delay_s",
                 "speed_limit_deg_s", "gripper_torque_nm"):
        low, high = getattr(DEFAULT_RANGES, name)
        values = [getattr(physics, name) for physics in drawn]
        assert low <= min(values) and max(values) <= high, name
        assert min(values) < low + 0.1 * (high - low) and max(values) > high - 0.1 * (high - low), name  # the whole range
    offsets = np.array([physics.calibration_offsets_deg for physics in drawn])
    assert offsets.shape == (200, 6) and np.abs(offsets).max() <= DEFAULT_RANGES.calibration_deg
    drawn_7 = {name: value for name, value in json.loads(json.dumps(asdict(draw_physics(7)))).items() if value is not None}
    assert physics_metadata("varied", 7) == {"physics": "varied", **drawn_7}  # no time constant: kept as before there was one


def test_a_ranges_file_varies_within_its_own_ranges_and_the_dataset_keeps_them(tmp_path):
    ranges = tmp_path / "narrow.json"
    ranges.write_text(json.dumps({"cube_size_m": [0.025, 0.025], "calibration_deg": 0}))
    mode = physics_mode(str(ranges))  # the ranges themselves, for nodes on any machine
    physics = physics_for(mode, 3)
    assert physics is not None and physics.cube_size_m == 0.025 and physics.calibration_offsets_deg == (0.0,) * 6
    assert physics.cube_mass_kg == draw_physics(3).cube_mass_kg  # the others: the documented ranges
    kept = physics_metadata(mode, 3)
    assert kept["physics"] == "varied" and PhysicsRanges(**{
        name: tuple(value) if isinstance(value, list) else value for name, value in kept["ranges"].items()
    }) == PhysicsRanges(cube_size_m=(0.025, 0.025), calibration_deg=0.0)
    # What the dataset keeps gives the episode's physics back (the eyes' pictures and the camera fit draw with it).
    assert physics_from_metadata(kept) == physics and physics_from_metadata(physics_metadata("fixed", 3)) is None
    with pytest.raises(ValueError, match="^an episode's varied physics has no 'gripper_torque_nm': it holds seed, "):
        physics_from_metadata({key: value for key, value in kept.items() if key != "gripper_torque_nm"})
    with pytest.raises(ValueError, match=r'^an episode.s physics is \{"physics": "fixed"\} or the varied values drawn, got'):
        physics_from_metadata({"physics": "wobbly"})


@pytest.mark.parametrize("text, message", [
    ("wobbly", "unknown physics 'wobbly'; use fixed, varied, or a JSON file of ranges"),
    ('{"cube_mass_kg": [-0.01, 0.05]}', "cube_mass_kg must be above 0, got [-0.01, 0.05]"),
    ('{"cube_size_m": [0.03, 0.05]}', "cube_size_m up to 0.05 m is larger than the jaws open (0.04 m between the pads)"),
    ('{"cube_size_m": [0.028, 0.022]}', "cube_size_m is [low, high], two numbers, low <= high; got [0.028, 0.022]"),
    ('{"cube_friction": 1.0}', "cube_friction is [low, high], two numbers, low <= high; got 1.0"),
    ('{"servo_damping": [-1, 1]}', "servo_damping must be >= 0, got [-1, 1]"),
    ('{"calibration_deg": [0, 2]}', "calibration_deg is a number of degrees >= 0"),
    ('{"gravity": [1, 2]}', "unknown range 'gravity'; the ranges are: calibration_deg, command_delay_s,"),
    ('[0.022, 0.028]', "a physics ranges file is a JSON object of ranges"),
    ("{", "ranges.json is not JSON (line 1: Expecting property name enclosed in double quotes)"),
    ("/no/such/ranges.json", "cannot read physics ranges /no/such/ranges.json: No such file or directory"),
])
def test_a_mode_or_ranges_that_make_no_sense_are_one_line(tmp_path, text, message):
    if text[0] in "[{":  # a ranges file's content
        (tmp_path / "ranges.json").write_text(text)
        text = str(tmp_path / "ranges.json")
    with pytest.raises(PhysicsError) as raised:
        physics_mode(text)
    assert message in str(raised.value) and "\n" not in str(raised.value)


def test_the_command_path_delays_limits_speed_and_is_off_by_the_calibration():
    physics = draw_physics(11)
    path = CommandPath(physics, HOME_POSE_DEG, slews=True)
    offsets = np.array(physics.calibration_offsets_deg)
    assert np.allclose(path.goal_deg, -offsets)  # home, where the arm believes it is
    assert np.allclose(path.reported(path.goal_deg), HOME_POSE_DEG)
    target = np.array([60.0, -30.0, 20.0, 10.0, -45.0, 30.0])
    path.send(target, now_s=1.0)
    tick = TICK_PERIOD_S
    before = [path.goal_at(1.0 + k * tick, tick).copy() for k in range(int(physics.command_delay_s / tick))]
    assert all(np.allclose(goal, -offsets) for goal in before)  # nothing moves before the delay is out
    goals = [path.goal_at(1.0 + physics.command_delay_s + k * tick, tick).copy() for k in range(1, 400)]
    steps = np.abs(np.diff(np.array(goals), axis=0))
    assert steps.max() <= physics.speed_limit_deg_s * tick + 1e-9  # never faster than the speed limit
    assert np.allclose(goals[-1], target - offsets)  # where the arm believes the target is
    # Fixed physics, on PyBullet (its motors cap the speed): the targets at once, reported as they are.
    fixed = CommandPath(NOMINAL, HOME_POSE_DEG, slews=False)
    fixed.send(target, now_s=0.0)
    assert np.array_equal(fixed.goal_at(0.0, tick), target) and np.array_equal(fixed.reported(target), target)
    assert fixed.settled
    # NOMINAL's cube is the task's (so101.bodies may not import the tasks, so it restates them).
    from so101.tasks.objects import Cube
    assert (NOMINAL.cube_half_size_m, NOMINAL.cube_mass_kg, NOMINAL.cube_friction) == \
        (Cube().half_size_m, Cube().mass_kg, Cube().friction)


@pytest.mark.parametrize("body", SIMULATED_BODIES)
def test_fixed_physics_is_the_nominal_point_of_the_same_servos(tmp_path, body):
    """A ranges file drawn to NOMINAL's values moves the arm as fixed physics does, on either simulator: one
    controller, whose fixed physics is its centre (the course's 3 rad/s, the gripper's 3.35 N·m). MuJoCo's fixed
    physics has no speed limit, as its MJCF: there the file's limit is out of reach."""
    speed_deg_s = NOMINAL.speed_limit_deg_s if body == "pybullet" else 1e6
    nominal = tmp_path / "nominal.json"
    nominal.write_text(json.dumps({name: value if name == "calibration_deg" else [value, value]
                                   for name, value in {**asdict(NOMINAL), "calibration_deg": 0.0,
                                                       "speed_limit_deg_s": speed_deg_s}.items()
                                   if name not in ("seed", "calibration_offsets_deg", "servo_time_constant_s")}))
    moves = [[40.0, -20.0, 30.0, -30.0, 60.0, 40.0], list(HOME_POSE_DEG)]
    paths = []
    for physics in ("fixed", str(nominal)):
        simulation = BODIES[body].body_class()(mode="direct", renders=False, time_step_s=TICK_PERIOD_S, physics=physics)
        try:
            path = []
            for targets in moves:
                simulation.set_targets_deg(targets)
                for _ in range(120):  # 0.48 s: 60 degrees at 3 rad/s, and settled
                    simulation.step()
                    path.append(simulation.joint_angles_deg())
            paths.append(np.array(path))
        finally:
            simulation.close()
    assert np.allclose(paths[0], paths[1], atol=1e-9)
    if body == "pybullet":  # no joint faster than the course's 3 rad/s, its motors' maxVelocity
        speeds = np.abs(np.diff(paths[0], axis=0)).max(axis=0) / TICK_PERIOD_S
        assert speeds.max() <= NOMINAL.speed_limit_deg_s * 1.01, speeds
    assert np.abs(paths[0][-1] - HOME_POSE_DEG).max() < 2.5  # and back home (MuJoCo's servos sag a little)


@pytest.mark.parametrize("body", SIMULATED_BODIES)
def test_both_simulators_apply_the_seeds_physics_and_report_as_its_calibration(body):
    seed = 21
    physics = draw_physics(seed)
    simulation = BODIES[body].body_class()(mode="direct", renders=False, time_step_s=TICK_PERIOD_S, task=CUBE_TO_BOX,
                                           seed=seed, physics="varied")
    try:
        assert simulation.physics == physics  # the same seed, the same physics, on either simulator
        assert np.allclose(simulation.joint_angles_deg(), HOME_POSE_DEG, atol=1e-6)  # home, as the arm believes it
        simulation.step(50)
        cube_z = float(simulation.scene.object_state()[2])
        assert abs(cube_z - physics.cube_half_size_m) < 0.0015  # the cube lies on the floor, its own size
        if body == "pybullet":
            import pybullet as p

            cube_id, client = simulation.scene.cube_id, simulation.client
            size = p.getCollisionShapeData(cube_id, -1, physicsClientId=client)[0][3]
            mass, friction = p.getDynamicsInfo(cube_id, -1, physicsClientId=client)[:2]
            joints = [state[0] for state in p.getJointStates(simulation.robot_id, simulation._indices,
                                                             physicsClientId=client)]
        else:
            model = simulation.model
            size = 2 * model.geom_size[model.geom("cube").id]
            mass, friction = model.body_mass[model.body("cube").id], model.geom_friction[model.geom("cube").id][0]
            joints = simulation.data.qpos[simulation._qpos]
            assert np.allclose(model.actuator_gainprm[simulation._actuators, 0], 17.8 * physics.servo_stiffness)
            assert model.actuator_forcerange[simulation._actuators[-1], 1] == pytest.approx(physics.gripper_torque_nm)
        assert np.allclose(size, physics.cube_size_m) and mass == pytest.approx(physics.cube_mass_kg)
        assert friction == pytest.approx(physics.cube_friction)
        # The engine's joints are where the arm believes it is, less the calibration's offsets.
        assert np.allclose(np.degrees(joints), np.array(simulation.joint_angles_deg()) - physics.calibration_offsets_deg)
        simulation.reset_task(seed + 1)
        assert simulation.physics == draw_physics(seed + 1)
    finally:
        simulation.close()


@pytest.mark.parametrize("body", SIMULATED_BODIES)
def test_the_arm_alone_takes_a_ranges_files_centre_its_goals_late_and_slower(body):
    """What `so101 replay --physics FILE` gives the body: no task, the ranges' centre, the calibration exact."""
    ranges = centred(PhysicsRanges(command_delay_s=(0.1, 0.2), speed_limit_deg_s=(50.0, 70.0)))
    assert ranges.command_delay_s == (0.15, 0.15) and ranges.calibration_deg == 0.0
    simulation = BODIES[body].body_class()(mode="direct", renders=False, time_step_s=TICK_PERIOD_S,
                                           physics=json.dumps(asdict(ranges)))
    try:
        assert simulation.physics is not None and simulation.physics.command_delay_s == 0.15
        start = simulation.joint_angles_deg()[0]
        simulation.set_targets_deg([start + 30, *HOME_POSE_DEG[1:]])
        simulation.step(round(0.14 / TICK_PERIOD_S))
        assert abs(simulation.joint_angles_deg()[0] - start) < 0.5  # the goal not taken yet
        simulation.step(round(0.26 / TICK_PERIOD_S))  # 0.25 s of motion at most: 15 degrees at 60 deg/s
        assert 8 < simulation.joint_angles_deg()[0] - start < 16
    finally:
        simulation.close()


@pytest.mark.parametrize("body", SIMULATED_BODIES)
@pytest.mark.parametrize("time_constant_s", [0.05, 0.1])
def test_a_servo_time_constant_is_reached_by_each_simulators_own_gain(body, time_constant_s):
    """What a fitted file asks for (`so101 physics --fit`): a small step's gap 63% closed in that time, each
    simulator setting its own gain (PyBullet's are 40 ms, MuJoCo's 68-80 ms, without one)."""
    ranges = {"servo_time_constant_s": [time_constant_s] * 2, "servo_damping": [1, 1], "command_delay_s": [0, 0],
              "calibration_deg": 0}
    simulation = BODIES[body].body_class()(mode="direct", renders=False, time_step_s=TICK_PERIOD_S,
                                           physics=json.dumps(ranges))
    try:
        simulation.step(250)  # at rest, sagged as it will be
        start = simulation.joint_angles_deg()
        simulation.set_targets_deg(start + 2.0)
        moved = []
        for _ in range(round(3 * time_constant_s / TICK_PERIOD_S) + 25):
            simulation.step()
            moved.append(simulation.joint_angles_deg() - start)
    finally:
        simulation.close()
    moved = np.array(moved)
    closed_s = (np.argmax(moved >= 0.632 * moved[-1], axis=0) + 1) * TICK_PERIOD_S
    assert np.all(np.abs(closed_s[:5] / time_constant_s - 1) < 0.2), closed_s


def test_the_pictures_show_the_seeds_cube_and_the_arm_where_it_truly_is():
    """By seed (the bodies' cameras), or an episode's physics given whole (a dataset's: the eyes' pictures, the
    camera fit), then fixed physics again."""
    from so101.bodies.task_cameras import TaskCameras

    physics = draw_physics(5)

    def shown(cameras) -> tuple[float, np.ndarray]:
        cameras.draw(HOME_POSE_DEG, [], 64, 48, wrist=False)
        drawn = cameras._model
        return 2 * float(drawn.model.geom_size[drawn.model.geom("cube").id][0]), drawn.joint_angles_deg() - HOME_POSE_DEG

    with TaskCameras(CUBE_TO_BOX, log=lambda line: None, physics="varied") as cameras:
        cameras.show_seed(5)
        size_m, off_deg = shown(cameras)
        assert size_m == pytest.approx(physics.cube_size_m) and np.allclose(off_deg, -np.array(physics.calibration_offsets_deg))
    with TaskCameras(CUBE_TO_BOX, log=lambda line: None) as cameras:
        cameras.show_physics(physics_from_metadata(physics_metadata("varied", 5)))
        size_m, off_deg = shown(cameras)
        assert size_m == pytest.approx(physics.cube_size_m) and np.allclose(off_deg, -np.array(physics.calibration_offsets_deg))
        cameras.show_physics(None)
        size_m, off_deg = shown(cameras)
        assert size_m == pytest.approx(2 * CUBE_TO_BOX.cube.half_size_m) and np.allclose(off_deg, 0.0, atol=1e-9)


def test_every_range_is_documented():
    from pathlib import Path

    page = (Path(__file__).resolve().parents[1] / "docs" / "loop" / "physics.md").read_text(encoding="utf-8")
    for spec in fields(PhysicsRanges):
        assert f"`{spec.name}`" in page, spec.name
