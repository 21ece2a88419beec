"""SO-101 facts, in one place: joint names, PyBullet indices, limits, home pose.

The limits are copied from `so101_new_calib.urdf` (radians there, degrees here);
`tests/test_simulator.py` checks them against the URDF that PyBullet loads.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Joint:
    """One actuated joint: its PyBullet index and its URDF limits in degrees."""

    index: int
    name: str
    lower_deg: float
    upper_deg: float
    label_zh: str
    label_en: str

    def clamp_deg(self, angle_deg: float) -> float:
        """The angle held within this joint's URDF limits."""
        return min(max(angle_deg, self.lower_deg), self.upper_deg)

    def allows_deg(self, angle_deg: float, decimals: int | None = None) -> bool:
        """Whether `angle_deg` is finite and within the limits; with `decimals`, within the limits
        as shown to that many places (110.0° for 109.99998°), so a value a person read is accepted."""
        lower, upper = self.lower_deg, self.upper_deg
        if decimals is not None:
            lower, upper = round(lower, decimals), round(upper, decimals)
        return math.isfinite(angle_deg) and lower <= angle_deg <= upper

    def limits_text(self) -> str:
        """The limits as people read them: "[-110.0°, 110.0°]"."""
        return f"[{self.lower_deg:.1f}°, {self.upper_deg:.1f}°]"


def _deg(rad: float) -> float:
    return math.degrees(rad)


# The five arm joints, in the order of `joint_cmd` batches and `joint_state`.
ARM_JOINTS: tuple[Joint, ...] = (
    Joint(0, "shoulder_pan", _deg(-1.91986), _deg(1.91986), "基座旋转", "base rotation"),
    Joint(1, "shoulder_lift", _deg(-1.74533), _deg(1.74533), "大臂抬起", "upper arm lift"),
    Joint(2, "elbow_flex", _deg(-1.69), _deg(1.69), "肘部弯曲", "elbow bend"),
    Joint(3, "wrist_flex", _deg(-1.65806), _deg(1.65806), "手腕俯仰", "wrist pitch"),
    Joint(4, "wrist_roll", _deg(-2.74385), _deg(2.84121), "手腕旋转", "wrist roll"),
)

# PyBullet index 5 is `gripper_frame_joint`, a fixed joint that only carries the
# gripper's reference frame; the moving jaw is index 6.
GRIPPER_FRAME_JOINT_INDEX = 5
GRIPPER = Joint(6, "gripper", _deg(-0.174533), _deg(1.74533), "夹爪", "gripper")

# Everything a command can move. Command index 5 means the gripper (PyBullet index 6).
ACTUATED_JOINTS: tuple[Joint, ...] = ARM_JOINTS + (GRIPPER,)
NUM_ARM_JOINTS = len(ARM_JOINTS)
GRIPPER_COMMAND_INDEX = NUM_ARM_JOINTS

# `so101_new_calib` puts each joint's zero near the middle of its range. The
# course's `home` (all zeros) stands the upper arm up and holds the forearm and
# gripper out level, forward: an "L" (see `so101 snapshot`, which renders it by default).
HOME_POSE_DEG: tuple[float, ...] = (0.0,) * len(ACTUATED_JOINTS)

# The joint table PyBullet reports for this URDF (course step A), index -> (name, type).
JOINT_TABLE: tuple[tuple[int, str, str], ...] = (
    (0, "shoulder_pan", "revolute"),
    (1, "shoulder_lift", "revolute"),
    (2, "elbow_flex", "revolute"),
    (3, "wrist_flex", "revolute"),
    (4, "wrist_roll", "revolute"),
    (5, "gripper_frame_joint", "fixed"),
    (6, "gripper", "revolute"),
)

def goal_deg(targets_deg) -> tuple[float, ...]:
    """Six goal angles in degrees (the five arm joints, then the gripper) as floats, checked
    as every body takes them; ValueError for any other count or a NaN/infinite angle."""
    try:
        goal = () if isinstance(targets_deg, (str, bytes)) else tuple(float(angle) for angle in targets_deg)
    except (TypeError, ValueError):
        goal = ()
    if len(goal) != len(ACTUATED_JOINTS) or not all(math.isfinite(angle) for angle in goal):
        raise ValueError(f"expected {len(ACTUATED_JOINTS)} finite angles in degrees, got {targets_deg!r}")
    return goal


# The course's motor settings: `maxVelocity=3.0` rad/s and
# `changeDynamics(linearDamping=0.2, angularDamping=0.2)`.
COURSE_MAX_VELOCITY_RAD_S = 3.0
COURSE_LINK_DAMPING = 0.2
# The URDF's `effort` limit for every joint, N·m.
URDF_EFFORT_LIMIT_NM = 10.0
