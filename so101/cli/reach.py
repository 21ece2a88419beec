"""`so101 reach`: how close IK and the simulated arm put the gripper tip to Cartesian targets.

The targets are points the arm can certainly reach: the tips of random poses. --seed fixes
the draw: five arm angles uniform inside the URDF limits, kept only if

- the tip is at least MIN_TIP_HEIGHT_MM above the floor (the simulation has a ground plane at
  z = 0: a target on it or under it would have the arm push into the floor), and
- the arm can move into the pose from home without meeting the floor on the way
  (`Kinematics.path_clear`): some points above the floor, low or curled round the base, are
  only reached by poses whose move from home sweeps the gripper through the floor, and the
  IK answer for them moves the same way. `--any-path` keeps those too, to see what happens.

Then, for each target:

1. IK (so101.kinematics) solves for it from home, as `xyz X Y Z` typed after `home` does;
2. the simulation takes the answer as the simulation node does: `SO101Sim(mode="direct",
   time_step_s=0.004, renders=False)`, `set_targets_deg(five + gripper 0)`, one 4 ms step
   per tick, until every joint is still (STILL_FOR_STEPS steps under STILL_DEG_S) or
   SETTLE_BUDGET_S has passed;
3. the tip is measured where the simulated arm put it (PyBullet's own frame of
   gripper_frame_link in the simulation), and its distance from the target is the settled error.

One simulator serves every target: before each, its joints are reset to home, at rest, with
home as the goal: the state a freshly loaded SO101Sim starts in, and a target reached after a
reset ends exactly where a fresh simulator's does (tests/test_kinematics.py checks it).
The goal the docs state (docs/jog.md): every target within GOAL_MM after settling. The exit code is 1
when a target is not, or when IK finds one out of reach.
"""

from __future__ import annotations

import argparse
import json
import math
import random
import time
from pathlib import Path
from typing import Any, NamedTuple

from so101.runtime.argtypes import number

MIN_TIP_HEIGHT_MM = 30.0
GOAL_MM = 5.0
SETTLE_BUDGET_S = 1.5
STILL_DEG_S = 0.5
STILL_FOR_STEPS = 10  # still for this many 4 ms steps in a row (40 ms): settled
MAX_DRAWS_PER_POINT = 100
MAX_POINTS = 100_000


def _points(text: str) -> int:
    accepted = number(lambda value: 1 <= value <= MAX_POINTS and value == int(value), f"a whole number from 1 to {MAX_POINTS}")
    return int(accepted(text))


def _seed(text: str) -> int:
    return int(number(lambda value: abs(value) < 2**53 and value == int(value), "a whole number")(text))


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    parser.add_argument("--points", type=_points, default=200, metavar="N", help="how many targets (default 200)")
    parser.add_argument(
        "--seed", type=_seed, default=1,
        help="seed of the random poses whose tips are the targets (default 1): the same seed, the same targets",
    )
    parser.add_argument(
        "--any-path", action="store_true",
        help="also keep targets whose drawn pose the arm cannot move into from home clear of the floor "
        "(set aside by default: IK's answer for such a point moves the same way, and the arm may jam on the floor)",
    )
    parser.add_argument(
        "--out", type=Path, default=None, metavar="FILE.json",
        help="also write the figures and every target (pose drawn, IK answer, settled pose and tip) to this JSON file",
    )
    parser.epilog = (
        f"Targets: tips of random poses inside the joint limits, at least {MIN_TIP_HEIGHT_MM:g} mm above the "
        f"ground plane (z = 0), that the arm moves to from home clear of the floor. IK solves each from home; "
        f"the PyBullet simulation, reset to home, drives there in 4 ms steps as the simulation node does, and "
        f"the tip is measured where the simulated arm stops. Exit code 1 when IK finds a target out of reach "
        f"or the settled tip is more than {GOAL_MM:g} mm from it."
    )


class Targets(NamedTuple):
    """The targets: (pose drawn, its tip) pairs, and how many poses were drawn and set aside."""

    pairs: list[tuple[tuple[float, ...], tuple[float, float, float]]]
    draws: int
    too_low: int  # tip under MIN_TIP_HEIGHT_MM
    near_floor: int  # the move there from home meets the floor (kept with any_path)


def draw_targets(kin, count: int, seed: int, any_path: bool = False) -> Targets:
    """`count` targets: the tips of random poses inside the limits, at least MIN_TIP_HEIGHT_MM
    above the floor, that the arm moves into from home clear of the floor (unless `any_path`)."""
    from so101.robot import ARM_JOINTS, HOME_POSE_DEG, NUM_ARM_JOINTS

    home = HOME_POSE_DEG[:NUM_ARM_JOINTS]
    draw = random.Random(seed)
    pairs: list[tuple[tuple[float, ...], tuple[float, float, float]]] = []
    draws, too_low, near_floor = 0, 0, 0
    while len(pairs) < count:
        if draws >= MAX_DRAWS_PER_POINT * count:  # does not happen with this arm: more than half qualify
            raise RuntimeError(f"drew {draws} poses and found only {len(pairs)} targets")
        draws += 1
        pose = tuple(draw.uniform(joint.lower_deg, joint.upper_deg) for joint in ARM_JOINTS)
        tip = kin.tip_mm(pose)
        if tip[2] < MIN_TIP_HEIGHT_MM:
            too_low += 1
            continue
        if not kin.path_clear(home, pose):
            near_floor += 1
            if not any_path:
                continue
        pairs.append((pose, tip))
    return Targets(pairs, draws, too_low, near_floor)


def reset_home(sim) -> None:
    """Put a SO101Sim back as it starts: every joint at home, at rest, and home as its goal."""
    import pybullet as p

    from so101.robot import ACTUATED_JOINTS, HOME_POSE_DEG

    for joint, angle_deg in zip(ACTUATED_JOINTS, HOME_POSE_DEG):
        p.resetJointState(sim.robot_id, joint.index, math.radians(angle_deg), 0.0, physicsClientId=sim.client)
    sim.set_targets_deg(HOME_POSE_DEG)


def settle(sim, goal_deg) -> tuple[int, bool]:
    """Command `goal_deg` (six angles) and step until every joint is still; (steps taken, still)."""
    import numpy as np

    sim.set_targets_deg(goal_deg)
    still_steps = 0
    budget = round(SETTLE_BUDGET_S / sim.time_step_s)
    for taken in range(1, budget + 1):
        sim.step()
        still_steps = still_steps + 1 if np.all(np.abs(sim.joint_velocities_deg_s()) < STILL_DEG_S) else 0
        if still_steps >= STILL_FOR_STEPS:
            return taken, True
    return budget, False


def sim_tip_mm(sim) -> tuple[float, float, float]:
    """Where the simulated arm's tip is: PyBullet's frame of gripper_frame_link in the simulation, in mm."""
    import pybullet as p

    from so101.kinematics import TIP_LINK_INDEX

    state = p.getLinkState(sim.robot_id, TIP_LINK_INDEX, computeForwardKinematics=True, physicsClientId=sim.client)
    return tuple(coordinate * 1000.0 for coordinate in state[4])


def _distance(a, b) -> float:
    return math.sqrt(sum((x - y) ** 2 for x, y in zip(a, b)))


def _figures(values: list[float]) -> dict[str, float]:
    from so101.stats import percentile

    return {"p50": percentile(values, 0.5), "p99": percentile(values, 0.99), "max": float(max(values))}


def run(args: argparse.Namespace) -> int:
    from so101.runtime.dataflow import TICK_PERIOD_S
    from so101.kinematics import FLOOR_CLEARANCE_MM, REACH_TOLERANCE_MM, Kinematics
    from so101.robot import GRIPPER_COMMAND_INDEX, HOME_POSE_DEG, NUM_ARM_JOINTS
    from so101.bodies.pybullet_sim import SO101Sim

    started = time.perf_counter()
    home = HOME_POSE_DEG[:NUM_ARM_JOINTS]
    gripper = HOME_POSE_DEG[GRIPPER_COMMAND_INDEX]
    records: list[dict[str, Any]] = []  # one per target, as the JSON report writes them
    ik_seconds, sim_seconds = 0.0, 0.0
    with Kinematics() as kin:
        targets = draw_targets(kin, args.points, args.seed, args.any_path)
        with SO101Sim(mode="direct", time_step_s=TICK_PERIOD_S, renders=False, log=lambda line: None) as sim:
            for pose, target in targets.pairs:
                clock = time.perf_counter()
                reach = kin.solve(target, seed_deg=home)
                ik_seconds += time.perf_counter() - clock
                clock = time.perf_counter()
                reset_home(sim)
                steps, still = settle(sim, reach.joints_deg + (gripper,))
                tip = sim_tip_mm(sim)
                sim_seconds += time.perf_counter() - clock
                records.append({
                    "pose_drawn_deg": list(pose), "target_mm": list(target),
                    "ik_joints_deg": list(reach.joints_deg), "ik_tip_mm": list(reach.tip_mm),
                    "ik_error_mm": reach.error_mm, "reachable": reach.reachable,
                    "settled_joints_deg": [float(angle) for angle in sim.joint_angles_deg()],
                    "settled_tip_mm": list(tip), "settled_error_mm": _distance(tip, target),
                    "settle_steps": steps, "still": still,
                })
    seconds = time.perf_counter() - started

    count = len(records)
    ik_figures = _figures([record["ik_error_mm"] for record in records])
    settled_figures = _figures([record["settled_error_mm"] for record in records])
    unreachable = sum(not record["reachable"] for record in records)
    beyond = sum(record["settled_error_mm"] > GOAL_MM for record in records)
    not_still = sum(not record["still"] for record in records)
    met = unreachable == 0 and beyond == 0
    kept = "kept" if args.any_path else "set aside"
    print(
        f"so101 reach: {count} targets, the tips of random poses (seed {args.seed}); "
        f"IK from home, the simulation reset to home before each"
    )
    print(
        f"poses drawn: {targets.draws}; set aside: {targets.too_low} with the tip under {MIN_TIP_HEIGHT_MM:g} mm; "
        f"{kept}: {targets.near_floor} whose move from home comes within {FLOOR_CLEARANCE_MM:g} mm of the floor"
    )
    print(f"{'error (mm)':<16}{'p50':>8}{'p99':>8}{'max':>8}")
    for label, figures in (("IK", ik_figures), ("settled tip", settled_figures)):
        print(f"{label:<16}" + "".join(f"{figures[key]:>8.2f}" for key in ("p50", "p99", "max")))
    print(f"out of reach for IK (more than {REACH_TOLERANCE_MM:g} mm off): {unreachable} of {count}")
    print(
        f"settled more than {GOAL_MM:g} mm from the target: {beyond} of {count}"
        + (f" (still moving after {SETTLE_BUDGET_S:g} s: {not_still})" if not_still else "")
    )
    print(
        f"time: {seconds:.1f} s (IK {ik_seconds:.1f} s, {ik_seconds / count * 1000:.1f} ms a target; "
        f"simulation {sim_seconds:.1f} s)"
    )
    print(f"goal, every target within {GOAL_MM:g} mm after settling: {'met' if met else 'NOT met'}")
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({
            "points": count, "seed": args.seed, "any_path": args.any_path, "draws": targets.draws,
            "set_aside_too_low": targets.too_low, "near_floor": targets.near_floor,
            "min_tip_height_mm": MIN_TIP_HEIGHT_MM, "start": "home", "time_step_s": TICK_PERIOD_S,
            "settle_budget_s": SETTLE_BUDGET_S, "goal_mm": GOAL_MM,
            "ik_error_mm": ik_figures, "settled_error_mm": settled_figures,
            "unreachable": unreachable, "beyond_goal": beyond, "not_still": not_still, "goal_met": met,
            "seconds": seconds, "ik_seconds": ik_seconds, "simulation_seconds": sim_seconds,
            "targets": records,
        }, indent=1) + "\n")
        print(f"wrote {args.out}")
    return 0 if met else 1
