"""The leader's readings as joint commands, and who drives when a person also types: plain code, no bus, no dora.

A leader reads as LeRobot's `so101_leader` reads it (its `DEGREES` and `RANGE_0_100` modes):
each joint's Present_Position, held inside its calibrated range, in degrees from the middle of
that range; the gripper as 0-100 across its range. The follower's command is that, with the
gripper's 0-100 mapped onto the follower's gripper degrees (so101/dataset/features.py, the one
place that mapping lives): a leader's fully open gripper opens the follower's fully.
"""

from __future__ import annotations

from typing import Mapping, Sequence

from so101.dataset.features import from_lerobot
from so101.feetech.calibration import DEG_PER_STEP, MOTOR_IDS, MotorCalibration
from so101.robot import GRIPPER_COMMAND_INDEX

# Typed commands take over until some leader joint has moved this far from where it was then:
# well above a servo's reading noise (a step or two, 0.1-0.2°), well below a deliberate move.
MOVED_DEG = 3.0


def leader_values(joint_index: int, steps: int, motor: MotorCalibration) -> float:
    """One leader joint as LeRobot reports it: degrees from the range's middle, or the gripper's 0-100."""
    bounded = min(max(steps, motor.range_min), motor.range_max)
    if joint_index == GRIPPER_COMMAND_INDEX:
        percent = (bounded - motor.range_min) / (motor.range_max - motor.range_min) * 100.0
        return 100.0 - percent if motor.drive_mode else percent
    degrees = (bounded - motor.middle_steps) * DEG_PER_STEP
    return -degrees if motor.drive_mode else degrees


def leader_command_deg(present_steps: Mapping[int, int], motors: Sequence[MotorCalibration]) -> tuple[float, ...]:
    """Six Present_Position readings (by servo ID) as the follower's six targets in the URDF's degrees."""
    lerobot = [leader_values(index, present_steps[servo_id], motor)
               for index, (servo_id, motor) in enumerate(zip(MOTOR_IDS, motors))]
    return tuple(float(angle) for angle in from_lerobot(lerobot))


class Takeover:
    """Who drives the body: the leader, until a typed command takes over; the leader again once
    it moves `moved_deg` from where it stood when the command came."""

    def __init__(self, moved_deg: float = MOVED_DEG):
        self.moved_deg = moved_deg
        self.typed = False  # a typed command drives
        self._leader_then_deg: tuple[float, ...] | None = None  # the leader when the typed command came

    def on_typed(self, leader_deg: tuple[float, ...] | None) -> bool:
        """A typed command arrived, the leader standing at `leader_deg` (None: not read yet).
        True when this takes over from the leader (the person is told once)."""
        took_over = not self.typed
        self.typed = True
        if took_over or self._leader_then_deg is None:
            self._leader_then_deg = leader_deg
        return took_over

    def leader_drives(self, leader_deg: tuple[float, ...]) -> bool:
        """Whether the leader's new reading goes to the body. Once it moved far enough, the leader
        drives again: `typed` turns False (the caller tells the person)."""
        if not self.typed:
            return True
        if self._leader_then_deg is None:  # typed before the leader's first reading: this one is "then"
            self._leader_then_deg = leader_deg
            return False
        if max(abs(now - then) for now, then in zip(leader_deg, self._leader_then_deg)) < self.moved_deg:
            return False
        self.typed = False
        self._leader_then_deg = None
        return True
