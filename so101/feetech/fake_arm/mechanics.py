"""The assembled arm the emulated bus stands for: where each joint's middle and hard stops fall on
its servo's encoder, and the degrees a factory-calibrated arm reads at each position."""

from __future__ import annotations

from dataclasses import dataclass

from so101.feetech import sts3215
from so101.robot import ACTUATED_JOINTS, GRIPPER_COMMAND_INDEX

MIDDLE = sts3215.STEPS_PER_TURN // 2

# The mechanical model, one row per servo: (ID, joint, assembly offset, hard stops?).
# The assembly offset is where the middle of the joint's travel lands on the servo's encoder,
# relative to 2048: a servo horn is never fitted exactly at mid-scale, so a calibration has real
# homing offsets to find (distinct, some negative, a few hundred steps). Joints with hard stops
# travel over their URDF range (so101/robot.py, converted at 4096 steps per 360°) centred on
# that middle; wrist_roll has no stops (it turns fully, its encoder wrapping 0..4095); the
# gripper's travel is its URDF span (-10° to 100°: 110°). At power-up every joint rests at its
# middle. No joint's travel crosses its encoder's 0/4095 seam.
MECHANICAL_TABLE: tuple[tuple[int, str, int, bool], ...] = (
    (1, "shoulder_pan", +310, True),
    (2, "shoulder_lift", -420, True),
    (3, "elbow_flex", +190, True),
    (4, "wrist_flex", -275, True),
    (5, "wrist_roll", +530, False),
    (6, "gripper", -360, True),
)


@dataclass(frozen=True)
class Mechanics:
    """One joint as assembled: physical encoder positions (steps) of its middle and stops."""

    servo_id: int
    joint: str
    centre: int
    lower: int | None  # hard stops; None for a joint that turns fully
    upper: int | None

    @property
    def has_stops(self) -> bool:
        return self.stops is not None

    @property
    def stops(self) -> tuple[int, int] | None:
        """The hard stops (lower, upper) in physical steps; None for a joint that turns fully."""
        return None if self.lower is None or self.upper is None else (self.lower, self.upper)

    def clamp(self, physical: float) -> float:
        """Where the joint can be: inside its stops, or on its encoder's turn."""
        if self.stops is None:
            return physical % sts3215.STEPS_PER_TURN
        lower, upper = self.stops
        return min(max(physical, lower), upper)


def _mechanics() -> dict[int, Mechanics]:
    by_name = {joint.name: joint for joint in ACTUATED_JOINTS}
    table = {}
    for servo_id, name, offset, has_stops in MECHANICAL_TABLE:
        centre = MIDDLE + offset
        lower = upper = None
        if has_stops:
            joint = by_name[name]
            half = round((joint.upper_deg - joint.lower_deg) / 360.0 * sts3215.STEPS_PER_TURN / 2)
            lower, upper = centre - half, centre + half
        table[servo_id] = Mechanics(servo_id, name, centre, lower, upper)
    return table


MECHANICS: dict[int, Mechanics] = _mechanics()
ALL_IDS = tuple(MECHANICS)
STEPS_PER_DEG = sts3215.STEPS_PER_TURN / 360.0
_GRIPPER = ACTUATED_JOINTS[GRIPPER_COMMAND_INDEX]


# -- degrees, as the factory-calibrated arm reads them (calibrate_as_at_the_factory) --------------


def script_steps(mechanics: Mechanics, angle_deg: float) -> float:
    """`angle_deg` in physical steps, held inside the stops; a joint without stops is not wrapped
    (a hand turning it past its encoder's seam moves on smoothly, in steps/s)."""
    if mechanics.joint == _GRIPPER.name and mechanics.stops is not None:
        lower, upper = mechanics.stops
        fraction = (angle_deg - _GRIPPER.lower_deg) / (_GRIPPER.upper_deg - _GRIPPER.lower_deg)
        steps = lower + fraction * (upper - lower)
    else:
        steps = mechanics.centre + angle_deg * STEPS_PER_DEG
    return steps if mechanics.stops is None else mechanics.clamp(steps)


def physical_steps(mechanics: Mechanics, angle_deg: float) -> float:
    """Where a joint at `angle_deg` stands on its encoder (physical steps, before any homing offset),
    clamped into its stops (wrist_roll, without stops, on its turn 0..4096). The degrees are what the
    arm calibrated as at the factory reads (so101/feetech/calibration.py steps_to_deg): joints 1-5 0° at
    the middle of their travel, 360° a turn; the gripper the URDF's -10°..100° across its stops."""
    return mechanics.clamp(script_steps(mechanics, angle_deg))


def joint_deg(mechanics: Mechanics, physical: float) -> float:
    """The inverse of physical_steps: the angle of a joint standing at `physical` steps (wrist_roll
    from -180° to 180°)."""
    if mechanics.joint == _GRIPPER.name and mechanics.stops is not None:
        lower, upper = mechanics.stops
        return _GRIPPER.lower_deg + (physical - lower) / (upper - lower) * (_GRIPPER.upper_deg - _GRIPPER.lower_deg)
    from_centre = physical - mechanics.centre
    if mechanics.stops is None:
        from_centre = (from_centre + MIDDLE) % sts3215.STEPS_PER_TURN - MIDDLE
    return from_centre / STEPS_PER_DEG
