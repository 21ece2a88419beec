"""The real arm's limits, checked on what the emulated bus was sent (so101 fake-arm's goals_written): each
Goal_Position inside its servo's calibrated range and its joint's URDF limits, and each one at most the
speed limit times the tick from the one before (so101.bodies.real_arm's ramp)."""

from __future__ import annotations

import math
from pathlib import Path

from so101.feetech.calibration import MOTOR_IDS, MOTOR_NAMES, deg_to_steps, load_calibration
from so101.robot import ACTUATED_JOINTS


def goals_beyond_the_limits(goals_by_servo: dict[int, tuple[int, ...]], calibration_file: Path,
                            max_speed_deg_s: float, tick_s: float) -> list[str]:
    """One line per goal outside a limit ([] when all kept them); `goals_by_servo`: servo id -> its goals in order.
    In steps, as sent: a bound is widened to the whole step the driver's rounding may reach."""
    calibration = load_calibration(calibration_file)
    beyond = []
    for index, (servo_id, name) in enumerate(zip(MOTOR_IDS, MOTOR_NAMES)):
        motor, joint, goals = calibration[name], ACTUATED_JOINTS[index], goals_by_servo[servo_id]
        # The joint's degrees map linearly onto its steps (the gripper's onto its whole calibrated range).
        ends = sorted(deg_to_steps(index, angle, motor) for angle in (joint.lower_deg, joint.upper_deg))
        lowest, highest = max(motor.range_min, math.floor(ends[0])), min(motor.range_max, math.ceil(ends[1]))
        largest_step = math.ceil(abs(deg_to_steps(index, max_speed_deg_s * tick_s, motor) - deg_to_steps(index, 0, motor)))
        beyond += [f"{name} goal {number}: {goal} outside {lowest}..{highest} (the calibrated range and {joint.limits_text()})"
                   for number, goal in enumerate(goals) if not lowest <= goal <= highest]
        beyond += [f"{name} goal {number}: {later - earlier:+d} steps in one tick, over {largest_step}"
                   for number, (earlier, later) in enumerate(zip(goals, goals[1:]), start=1)
                   if abs(later - earlier) > largest_step]
    return beyond
