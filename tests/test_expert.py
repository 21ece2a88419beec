"""The scripted expert (so101/tasks/expert.py), in process on both simulators: its plan, its success on
seeded layouts by the task's own success function, its noise, and its recovery from a missed grasp
(a cube knocked away, or a grasp put beside it on purpose)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from so101.bodies.registry import BODIES, SIMULATED_BODIES
from so101.robot import HOME_POSE_DEG
from so101.tasks import CUBE_TO_BOX
from so101.tasks.expert import (
    APPROACH_ABOVE_M, CLOSED_DEG, MISS_ASIDE_M, OPEN_DEG, CubeSeen, Expert, planner_for, quarter_turn_rad, seen_in,
)
from so101.kinematics import TIP_LINK_INDEX
from so101.tasks.news import LANDED, BoxNews

pytestmark = pytest.mark.slow  # steps both simulators for simulated minutes

FPS = 25
STEPS_PER_FRAME = 10  # of 4 ms
SEEDS = (0, 1, 2, 3, 4)


@pytest.fixture(scope="module")
def planner():
    planner = planner_for(CUBE_TO_BOX)
    yield planner
    planner.close()


def make(body_name, seed):
    return BODIES[body_name].body_class()(mode="direct", time_step_s=0.004, renders=False, log=lambda line: None,
                                          task=CUBE_TO_BOX, seed=seed)


def run_episode(sim, expert, time_limit_s=30.0, disturb=None):
    """The expert drives `sim` frame by frame, as the lockstep body does; the task's success ends it.
    Returns (succeeded, seconds, the six targets of every frame)."""
    targets = []
    for frame in range(int(time_limit_s * FPS)):
        if disturb is not None:
            disturb(frame, sim, expert)
        object_state = sim.scene.object_state()
        if sim.scene.succeeded():
            return True, frame / FPS, targets
        targets.append(expert.targets(frame / FPS, sim.joint_angles_deg(), object_state))
        sim.set_targets_deg(targets[-1])
        sim.step(STEPS_PER_FRAME)
    return False, time_limit_s, targets


def test_the_yaw_of_a_cube_is_read_from_its_quaternion():
    for yaw_deg in (-44.0, 0.0, 12.5, 44.0):
        layout = CUBE_TO_BOX.layout(0)
        state = [*layout.cube_xyz_m, 0.0, 0.0, math.sin(math.radians(yaw_deg) / 2), math.cos(math.radians(yaw_deg) / 2),
                 *layout.box_xyz_m]
        seen = seen_in(state)
        assert seen.cube_yaw_rad == pytest.approx(math.radians(yaw_deg))
        assert seen.cube_xyz_m == layout.cube_xyz_m and seen.box_xyz_m == layout.box_xyz_m


def test_a_cube_turned_by_quarter_turns_shows_the_same_yaw_within_45_degrees():
    for yaw_deg, shown_deg in ((0.0, 0.0), (44.0, 44.0), (46.0, -44.0), (-46.0, 44.0), (100.0, 10.0), (-170.0, 10.0)):
        assert math.degrees(quarter_turn_rad(math.radians(yaw_deg))) == pytest.approx(shown_deg)


def test_the_wrist_roll_at_the_grasp_follows_the_cubes_yaw_with_no_jump(planner):
    # A policy learns the grasp from plans like these: the roll must be a smooth function of what it
    # sees. Where the cube stands, turned from -44° to 44° by 2°, the roll steps by the 2° and never
    # by a quarter turn (the wrist least turned, as first chosen, jumped 90° halfway).
    for seed in (0, 7):
        layout = CUBE_TO_BOX.layout(seed)
        rolls = []
        for yaw_deg in range(-44, 45, 2):
            plan = planner.plan(CubeSeen(layout.cube_xyz_m, math.radians(yaw_deg), layout.box_xyz_m), HOME_POSE_DEG)
            rolls.append(next(w for w in plan if w.phase == "close").targets_deg[4])
        steps = np.abs(np.diff(rolls))
        assert steps.max() < 3.0, (seed, rolls)


def grasp_point_m(planner, arm_deg):
    """Where the jaws close, for the arm's five angles."""
    tip, rows = planner.kinematics.frame_m(TIP_LINK_INDEX, arm_deg)
    return np.asarray(tip) + np.asarray(rows).reshape(3, 3) @ planner.grasp.point_in_tip_m


@pytest.mark.parametrize("seed", SEEDS)
def test_the_plan_opens_above_the_cube_closes_on_it_and_lets_go_inside_the_box(planner, seed):
    layout = CUBE_TO_BOX.layout(seed)
    plan = planner.plan(CubeSeen(layout.cube_xyz_m, layout.cube_yaw_rad, layout.box_xyz_m), HOME_POSE_DEG)
    phases = [waypoint.phase for waypoint in plan]
    assert phases[0] == "approach" and phases[-1] == "home"
    assert phases.index("close") < phases.index("lift") < phases.index("carry") < phases.index("release")
    approach, closing = plan[0], plan[phases.index("close")]
    cube = np.asarray(layout.cube_xyz_m)
    assert approach.targets_deg[-1] == OPEN_DEG and closing.targets_deg[-1] == CLOSED_DEG
    # Above the cube by the approach height, then on it, within a millimetre.
    assert np.linalg.norm(grasp_point_m(planner, approach.targets_deg[:5]) - (cube + [0, 0, APPROACH_ABOVE_M])) < 0.001
    assert np.linalg.norm(grasp_point_m(planner, closing.targets_deg[:5]) - cube) < 0.001
    # Let go where the cube falls inside the box's walls, below their top.
    released = grasp_point_m(planner, plan[phases.index("release")].targets_deg[:5]) - np.asarray(layout.box_xyz_m)
    inner = CUBE_TO_BOX.box.inner_half_m - CUBE_TO_BOX.cube.half_size_m
    assert abs(released[0]) < inner and abs(released[1]) < inner and released[2] < CUBE_TO_BOX.box.wall_height_m
    # No move is a jump: each is paced, the fastest joint at most 90°/s.
    start = HOME_POSE_DEG
    for waypoint in plan:
        assert max(abs(a - b) for a, b in zip(waypoint.targets_deg, start)) / waypoint.move_s <= 90.0 + 1e-6
        start = waypoint.targets_deg


@pytest.mark.parametrize("body_name", SIMULATED_BODIES)
def test_the_expert_puts_the_cube_in_the_box_on_each_seeded_layout(planner, body_name):
    times = []
    for seed in SEEDS:
        with make(body_name, seed) as sim:
            expert = Expert(planner, seed=seed)
            succeeded, seconds, _ = run_episode(sim, expert)
        assert succeeded, f"seed {seed} on {body_name}: the cube is not in the box after 30 s"
        assert expert.attempts == 1
        times.append(seconds)
    assert all(5.0 < seconds < 15.0 for seconds in times), times


@pytest.mark.parametrize("body_name", SIMULATED_BODIES)
def test_the_news_says_in_the_box_once_while_the_release_jolts_the_cube(planner, body_name):
    # As at the prompt's `expert`: the plan played to its end, the body judging every 4 ms tick. At seed 12
    # the jaws opening and the arm leaving jolt the cube, the success function flickers; the news does not.
    news, said, judged = BoxNews(), [], []
    with make(body_name, 12) as sim:
        expert = Expert(planner)
        for step in range(int(30.0 / 0.004)):
            if step % STEPS_PER_FRAME == 0:
                sim.set_targets_deg(expert.targets(step * 0.004, sim.joint_angles_deg(), sim.scene.object_state()))
                if expert.done:
                    break
            sim.step(1)
            judged.append(sim.scene.succeeded())
            said.append(news.update(judged[-1], sim.scene.object_state()))
    assert expert.done and judged[-1]
    assert np.count_nonzero(np.diff(judged)) > 1  # the flicker is there to be smoothed
    assert [piece for piece in said if piece is not None] == [LANDED]


@pytest.mark.parametrize("body_name", SIMULATED_BODIES)
def test_with_noise_the_path_differs_and_the_cube_still_goes_in(planner, body_name):
    seed = 2
    with make(body_name, seed) as sim:
        _, _, plain = run_episode(sim, Expert(planner, seed=seed))
    with make(body_name, seed) as sim:
        succeeded, _, noisy = run_episode(sim, Expert(planner, noise=1.0, seed=seed))
    assert succeeded
    frames = min(len(plain), len(noisy))
    assert np.abs(np.array(plain[:frames]) - np.array(noisy[:frames])).max() > 2.0  # degrees


@pytest.mark.parametrize("body_name", SIMULATED_BODIES)
def test_a_cube_knocked_away_after_the_grasp_is_picked_up_again(planner, body_name):
    seed = 1
    layout = CUBE_TO_BOX.layout(seed)
    moved = False

    def knock_away(frame, sim, expert):  # as the jaws close, the cube is elsewhere: the lift finds it down
        nonlocal moved
        if not moved and expert.phase == "close":
            moved = True
            sim.scene.lay_out(type(layout)(seed, (0.2, -0.12, layout.cube_xyz_m[2]), 0.3, layout.box_xyz_m))

    with make(body_name, seed) as sim:
        expert = Expert(planner, seed=seed)
        succeeded, _, _ = run_episode(sim, expert, disturb=knock_away)
    assert moved and succeeded
    assert expert.attempts == 2


@pytest.mark.parametrize("body_name", SIMULATED_BODIES)
def test_a_grasp_missed_on_purpose_closes_beside_the_cube_and_the_recovery_puts_it_in(planner, body_name):
    seed = 3
    cube_xy = np.asarray(CUBE_TO_BOX.layout(seed).cube_xyz_m[:2])
    first_plans = []

    def keep_the_first_plan(frame, sim, expert):
        if frame == 1:
            first_plans.append(list(expert.plan))

    with make(body_name, seed) as sim:
        expert = Expert(planner, seed=seed, misses=1.0)
        succeeded, seconds, _ = run_episode(sim, expert, disturb=keep_the_first_plan)
    (plan,) = first_plans
    closing = next(waypoint for waypoint in plan if waypoint.phase == "close")
    aside_m = np.linalg.norm(grasp_point_m(planner, closing.targets_deg[:5])[:2] - cube_xy)
    assert MISS_ASIDE_M[0] - 0.001 < aside_m < MISS_ASIDE_M[1] + 0.001
    assert succeeded and expert.attempts == 2, (succeeded, expert.attempts, seconds)


@pytest.mark.parametrize("body_name", SIMULATED_BODIES)
@pytest.mark.parametrize("phase, held, first_phase", [("descend", False, "approach"), ("carry", True, "carry"),
                                                      ("lower", True, "lower")])
def test_an_expert_taking_over_mid_episode_finishes_from_where_things_are(planner, body_name, phase, held, first_phase):
    """DAgger's labeller (so101 demos --learner): a fresh expert, given the arm and the cube as another sender left
    them, plans from there: a cube on the floor is grasped again from above; a held one is carried on (or let go
    over the box) in one attempt, never dropped on the way."""
    seed = 3
    first = Expert(planner, seed=seed)
    fresh = Expert(planner, seed=seed)
    seen_held = []

    class Relay:  # the first expert drives until it is in `phase`, then the fresh one from that frame on
        phase = ""

        def targets(self, now_s, joints_deg, object_state):
            if not seen_held and first.phase != phase:
                return first.targets(now_s, joints_deg, object_state)
            if not seen_held:
                seen_held.append(planner.holds_cube(seen_in(object_state), joints_deg))
            return fresh.targets(now_s, joints_deg, object_state)

    with make(body_name, seed) as sim:
        succeeded, seconds, _ = run_episode(sim, Relay())
    assert seen_held == [held]
    assert fresh.plan[0].phase == first_phase
    assert succeeded and fresh.attempts == 1, (succeeded, seconds, fresh.attempts)
