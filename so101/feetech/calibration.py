"""The real arms' calibration: LeRobot's `so101_follower` (and `so101_leader`) JSON and the step <-> degree maths.

Plain functions, no serial port, tested directly. The file is LeRobot's, read as it is (the
leader's has the follower's format, motor names and IDs):
per motor name, `id`, `drive_mode`, `homing_offset`, `range_min`, `range_max` (steps, after
the servo applies its Homing_Offset). `so101 calibrate` writes the same format.

Angles follow LeRobot's degree convention, which `so101_new_calib.urdf` was made for:
0° at the middle of the calibrated range, 4096 steps per turn (LeRobot divides by 4095;
the difference is under 0.05° over a joint's whole range), `drive_mode` 1 inverting the
direction. The gripper's calibrated range maps linearly onto the URDF's gripper range.
A per-joint sign (`SO101_JOINT_SIGNS`) flips a joint whose direction does not match the URDF.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal, Mapping, Sequence

from so101.robot import ACTUATED_JOINTS, GRIPPER_COMMAND_INDEX
from so101.feetech.sts3215 import MAX_STEP, STEPS_PER_TURN

# LeRobot's motor names for the SO-101 follower, and their bus IDs: the URDF's joint names.
MOTOR_NAMES: tuple[str, ...] = tuple(joint.name for joint in ACTUATED_JOINTS)
MOTOR_IDS: tuple[int, ...] = tuple(range(1, len(MOTOR_NAMES) + 1))
FIELDS = ("id", "drive_mode", "homing_offset", "range_min", "range_max")
# Homing_Offset is 11 bits and a sign on the servo.
MAX_HOMING_OFFSET = 2047
# A range narrower than this (about 9°) cannot be a joint moved through its travel.
MIN_RANGE_STEPS = 100
DEG_PER_STEP = 360.0 / STEPS_PER_TURN


class CalibrationError(ValueError):
    """A calibration file that cannot be used; the message is one line for the user."""


@dataclass(frozen=True)
class MotorCalibration:
    id: int
    drive_mode: int
    homing_offset: int
    range_min: int
    range_max: int

    @property
    def middle_steps(self) -> float:
        return (self.range_min + self.range_max) / 2


Calibration = dict[str, MotorCalibration]
# Which arm of the pair a file calibrates: LeRobot's so101_follower or so101_leader.
Role = Literal["follower", "leader"]


def _motor(name: str, raw: object, source: str) -> MotorCalibration:
    if not isinstance(raw, dict):
        raise CalibrationError(f"{source}: {name} is not an object with {', '.join(FIELDS)}")
    missing = [key for key in FIELDS if key not in raw]
    if missing:
        raise CalibrationError(f"{source}: {name} has no {', '.join(missing)}")
    values = {}
    for key in FIELDS:
        value = raw[key]
        if isinstance(value, bool) or not isinstance(value, int):
            raise CalibrationError(f"{source}: {name}.{key} = {value!r} is not a whole number")
        values[key] = value
    motor = MotorCalibration(**values)
    if motor.drive_mode not in (0, 1):
        raise CalibrationError(f"{source}: {name}.drive_mode = {motor.drive_mode}: accepted 0 or 1")
    if abs(motor.homing_offset) > MAX_HOMING_OFFSET:
        raise CalibrationError(f"{source}: {name}.homing_offset = {motor.homing_offset} is outside ±{MAX_HOMING_OFFSET}")
    if not 0 <= motor.range_min < motor.range_max <= MAX_STEP:
        raise CalibrationError(
            f"{source}: {name} range {motor.range_min}..{motor.range_max} must satisfy 0 <= range_min < range_max <= {MAX_STEP}"
        )
    return motor


def parse_calibration(document: object, source: str = "calibration", role: Role = "follower") -> Calibration:
    """LeRobot's so101_follower (or so101_leader) calibration (a parsed JSON document), checked;
    CalibrationError says what is wrong."""
    if not isinstance(document, dict):
        raise CalibrationError(f"{source}: expected a JSON object with the motors {', '.join(MOTOR_NAMES)}")
    missing = [name for name in MOTOR_NAMES if name not in document]
    if missing:
        raise CalibrationError(f"{source}: no calibration for {', '.join(missing)} (an SO-101 {role} has {', '.join(MOTOR_NAMES)})")
    calibration = {name: _motor(name, document[name], source) for name in MOTOR_NAMES}
    for name, expected_id in zip(MOTOR_NAMES, MOTOR_IDS):
        if calibration[name].id != expected_id:
            raise CalibrationError(f"{source}: {name}.id = {calibration[name].id}, but the SO-101 {role}'s {name} is ID {expected_id}")
    return calibration


def load_calibration(path: str | Path, role: Role = "follower") -> Calibration:
    path = Path(path).expanduser()
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise CalibrationError(f"no calibration file {path}") from None
    except OSError as error:
        raise CalibrationError(f"cannot read the calibration file {path}: {error.strerror or error}") from None
    try:
        document = json.loads(text)
    except json.JSONDecodeError as error:
        raise CalibrationError(f"{path} is not JSON ({error.msg}, line {error.lineno})") from None
    return parse_calibration(document, str(path), role)


def calibration_document(calibration: Mapping[str, MotorCalibration]) -> dict:
    return {name: asdict(calibration[name]) for name in MOTOR_NAMES}


def save_calibration(path: str | Path, calibration: Mapping[str, MotorCalibration]) -> None:
    """Write LeRobot's format; the file is replaced whole, so a failed write leaves the old one."""
    path = Path(path).expanduser()
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(path.name + ".partial")
    partial.write_text(json.dumps(calibration_document(calibration), indent=4) + "\n", encoding="utf-8")
    partial.replace(path)


def parse_joint_signs(text: str) -> tuple[int, ...]:
    """`SO101_JOINT_SIGNS`: six values, each 1 or -1, in joint order ("1,1,-1,1,1,1")."""
    parts = [part.strip() for part in text.replace(" ", ",").split(",") if part.strip()]
    if len(parts) != len(MOTOR_NAMES) or any(part not in ("1", "-1", "+1") for part in parts):
        raise ValueError(f"SO101_JOINT_SIGNS={text!r}: expected {len(MOTOR_NAMES)} values of 1 or -1, comma-separated, in the order {', '.join(MOTOR_NAMES)}")
    return tuple(int(part) for part in parts)


def _direction(motor: MotorCalibration, sign: int) -> int:
    return -sign if motor.drive_mode else sign


def steps_to_deg(joint_index: int, steps: float, motor: MotorCalibration, sign: int = 1) -> float:
    """A Present_Position (steps) as the URDF's joint angle in degrees."""
    direction = _direction(motor, sign)
    if joint_index == GRIPPER_COMMAND_INDEX:
        joint = ACTUATED_JOINTS[joint_index]
        fraction = (steps - motor.range_min) / (motor.range_max - motor.range_min)
        if direction < 0:
            fraction = 1.0 - fraction
        return joint.lower_deg + fraction * (joint.upper_deg - joint.lower_deg)
    return direction * (steps - motor.middle_steps) * DEG_PER_STEP


def deg_to_steps(joint_index: int, angle_deg: float, motor: MotorCalibration, sign: int = 1) -> float:
    """The inverse of steps_to_deg (not rounded, not clamped)."""
    direction = _direction(motor, sign)
    if joint_index == GRIPPER_COMMAND_INDEX:
        joint = ACTUATED_JOINTS[joint_index]
        fraction = (angle_deg - joint.lower_deg) / (joint.upper_deg - joint.lower_deg)
        if direction < 0:
            fraction = 1.0 - fraction
        return motor.range_min + fraction * (motor.range_max - motor.range_min)
    return motor.middle_steps + direction * angle_deg / DEG_PER_STEP


def goal_steps(joint_index: int, angle_deg: float, motor: MotorCalibration, sign: int = 1) -> int:
    """A goal angle as the Goal_Position to write: rounded and clamped to the calibrated range."""
    steps = deg_to_steps(joint_index, angle_deg, motor, sign)
    return int(min(max(round(steps), motor.range_min), motor.range_max))


def step_toward(current_deg: Sequence[float], target_deg: Sequence[float], max_step_deg: float) -> tuple[float, ...]:
    """Each angle moved toward its target by at most `max_step_deg` (the per-tick ramp)."""
    return tuple(
        current + min(max(target - current, -max_step_deg), max_step_deg)
        for current, target in zip(current_deg, target_deg)
    )


def homing_offset(middle_position_steps: int) -> int:
    """The Homing_Offset that makes a joint read mid-scale (2047) where it stands now (raw
    position, read with offset 0): LeRobot's half-turn homing."""
    return int(middle_position_steps) - MAX_STEP // 2
