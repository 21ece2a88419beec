"""A grasp from above: where the gripper tip goes so that a cube's centre sits between the pads.

The tip (`gripper_frame_link`) lies at the fixed jaw; the moving jaw swings toward it. So the
point to put on the cube's centre is beside the tip: the fixed pad's inner face, plus a
clearance and half the cube, along the jaws' axis (the tip frame's -x). `TopDownGrasp` finds that
point from the pads (so101.bodies.jaw_pads, grown as the simulators have them) and the
kinematics, and gives the five arm angles that hold the gripper pointing straight down, its jaws
across a yaw, with that point at a place: at exactly that yaw (`pose_at_yaw`), or, since a cube
is the same every 90°, at the one of the four whose wrist roll is within its limits and nearest
0 (`pose`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from so101.bodies.jaw_pads import JawPad
from so101.kinematics import TIP_LINK_INDEX, Kinematics
from so101.robot import ARM_JOINTS

GRIPPER_LINK_INDEX = ARM_JOINTS[-1].index  # the fixed jaw's link: the child of wrist_roll
WRIST_ROLL = ARM_JOINTS[-1]
# A pose off by more than these is not a grasp from above.
MAX_POSITION_ERROR_MM = 1.0
MAX_ANGLE_ERROR_DEG = 2.0


@dataclass(frozen=True)
class GraspPose:
    arm_deg: tuple[float, ...]  # the five arm angles
    yaw_rad: float  # the jaws' yaw taken (the asked one, give or take quarter turns)
    position_error_mm: float
    angle_error_deg: float

    @property
    def exact(self) -> bool:
        return self.position_error_mm <= MAX_POSITION_ERROR_MM and self.angle_error_deg <= MAX_ANGLE_ERROR_DEG


def top_down_rotation(yaw_rad: float) -> np.ndarray:
    """The tip frame pointing down (its z, the approach, along -z) with its x (the jaws' axis) at `yaw_rad`."""
    x_axis = np.array([math.cos(yaw_rad), math.sin(yaw_rad), 0.0])
    z_axis = np.array([0.0, 0.0, -1.0])
    return np.column_stack([x_axis, np.cross(z_axis, x_axis), z_axis])


class TopDownGrasp:
    """Grasps from above of a cube of `cube_half_m` with the fixed jaw's `fixed_pad`, on `kinematics`; the
    cube's face `clearance_m` from the pad's when the jaws come down around it (the moving jaw, closing,
    pushes it across)."""

    def __init__(self, kinematics: Kinematics, fixed_pad: JawPad, cube_half_m: float, clearance_m: float = 0.0):
        self.kinematics = kinematics
        gripper_xyz, gripper_rows = kinematics.frame_m(GRIPPER_LINK_INDEX)
        tip_xyz, tip_rows = kinematics.frame_m(TIP_LINK_INDEX)
        gripper_rotation = np.asarray(gripper_rows).reshape(3, 3)
        tip_rotation = np.asarray(tip_rows).reshape(3, 3)
        inward = np.asarray(fixed_pad.inward)
        # The cube's centre `clearance_m` off the fixed pad's face, in the gripper link's frame...
        centre = np.asarray(fixed_pad.pos_m) + inward * (fixed_pad.half_size_m[0] + clearance_m + cube_half_m)
        world = np.asarray(gripper_xyz) + gripper_rotation @ centre
        # ...and in the tip's.
        self.point_in_tip_m = tip_rotation.T @ (world - np.asarray(tip_xyz))

    def pose(self, point_m: Sequence[float], yaw_rad: float, seed_deg: Sequence[float] | None = None) -> GraspPose:
        """The arm angles that put the grasp point at `point_m` (base frame), pointing down, jaws
        across `yaw_rad` or a quarter turn from it: the best of the four (see _rank)."""
        best: GraspPose | None = None
        for quarter in range(4):
            candidate = self.pose_at_yaw(point_m, yaw_rad + quarter * math.pi / 2, seed_deg)
            if best is None or _rank(candidate) < _rank(best):
                best = candidate
        assert best is not None
        return best

    def pose_at_yaw(self, point_m: Sequence[float], yaw_rad: float, seed_deg: Sequence[float] | None = None,
                    max_starts: int | None = None) -> GraspPose:
        """The arm angles that put the grasp point at `point_m`, pointing down, jaws across exactly
        `yaw_rad` (a grasp's next waypoint: the yaw taken, `seed_deg` the one before, near it)."""
        rotation = top_down_rotation(yaw_rad)
        tip_m = np.asarray(point_m, dtype=np.float64) - rotation @ self.point_in_tip_m
        arm_deg, position_mm, angle_deg = self.kinematics.solve_oriented(tip_m * 1000.0, rotation, seed_deg, max_starts)
        return GraspPose(arm_deg, yaw_rad, position_mm, angle_deg)


def _rank(pose: GraspPose) -> tuple[bool, float]:
    """Exact poses first, then the wrist roll nearest 0 (least twist, farthest from its limits)."""
    return (not pose.exact, abs(pose.arm_deg[-1]) if pose.exact else pose.position_error_mm + pose.angle_error_deg)
