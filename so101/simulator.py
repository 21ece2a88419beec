"""The one class that talks to PyBullet: an SO-101 on a ground plane.

Each instance owns its own physics client and passes `physicsClientId` on every
call, so several simulators can live in one process. Angles cross this boundary
in degrees; PyBullet's radians stay inside.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
import pybullet as p
import pybullet_data

from so101 import assets
from so101.display import resolve_mode
from so101.robot import (
    ACTUATED_JOINTS,
    COURSE_LINK_DAMPING,
    COURSE_MAX_VELOCITY_RAD_S,
    HOME_POSE_DEG,
)

JOINT_TYPE_NAMES = {
    p.JOINT_REVOLUTE: "revolute",
    p.JOINT_PRISMATIC: "prismatic",
    p.JOINT_SPHERICAL: "spherical",
    p.JOINT_PLANAR: "planar",
    p.JOINT_FIXED: "fixed",
}


@dataclass(frozen=True)
class JointInfo:
    """A row of `getJointInfo`, limits in degrees for revolute joints (radians as PyBullet reports them too)."""

    index: int
    name: str
    type: str
    lower_rad: float
    upper_rad: float
    max_force: float
    max_velocity: float


class SO101Sim:
    """An SO-101 arm on a fixed base, stepped by hand.

    targets and states are in degrees, in the order of `so101.robot.ACTUATED_JOINTS`:
    the five arm joints, then the gripper.
    """

    def __init__(
        self,
        mode: str = "auto",
        time_step_s: float = 1.0 / 240.0,
        assets_dir: Path | str | None = None,
        link_damping: float | None = COURSE_LINK_DAMPING,
        max_velocity_rad_s: float = COURSE_MAX_VELOCITY_RAD_S,
        log=print,
    ):
        # Resolve the model first: a missing file must give our message, not PyBullet's.
        urdf = assets.urdf_path(assets_dir)
        self.mode, notice = resolve_mode(mode)
        if notice:
            log(notice)
        self.time_step_s = float(time_step_s)
        self.client = p.connect(p.GUI if self.mode == "gui" else p.DIRECT)
        if self.client < 0:
            raise RuntimeError(f"PyBullet could not connect in {self.mode.upper()} mode")
        cid = self.client
        if self.mode == "gui":
            p.configureDebugVisualizer(p.COV_ENABLE_GUI, 0, physicsClientId=cid)
            p.resetDebugVisualizerCamera(0.6, 45, -30, [0, 0, 0.15], physicsClientId=cid)
        p.setAdditionalSearchPath(pybullet_data.getDataPath(), physicsClientId=cid)
        p.setGravity(0, 0, -9.81, physicsClientId=cid)
        p.setPhysicsEngineParameter(fixedTimeStep=self.time_step_s, physicsClientId=cid)
        self.plane_id = p.loadURDF("plane.urdf", physicsClientId=cid)
        self.robot_id = p.loadURDF(
            str(urdf), basePosition=[0, 0, 0], baseOrientation=[0, 0, 0, 1],
            useFixedBase=True, physicsClientId=cid,
        )
        self.joints = [self._joint_info(i) for i in range(p.getNumJoints(self.robot_id, physicsClientId=cid))]
        self._indices = [joint.index for joint in ACTUATED_JOINTS]
        self._forces = [self.joints[i].max_force for i in self._indices]
        if link_damping is not None:
            # The course's setting. Note: these are drag coefficients on the links'
            # Cartesian motion, not joint damping (see README, exercise 2).
            for index in range(-1, len(self.joints)):
                p.changeDynamics(
                    self.robot_id, index, linearDamping=link_damping, angularDamping=link_damping,
                    physicsClientId=cid,
                )
        self.max_velocity_rad_s = float(max_velocity_rad_s)
        self._goal_rad = np.radians(np.asarray(HOME_POSE_DEG, dtype=float))
        # The target actually sent to the motors: it moves toward the goal at no more
        # than max_velocity, which is what the course's `maxVelocity=3.0` gives
        # (setJointMotorControlArray has no maxVelocity argument).
        self._command_rad = self._goal_rad.copy()
        self.steps = 0

    # -- set-up helpers --------------------------------------------------------------
    def _joint_info(self, index: int) -> JointInfo:
        info = p.getJointInfo(self.robot_id, index, physicsClientId=self.client)
        return JointInfo(
            index=info[0], name=info[1].decode(), type=JOINT_TYPE_NAMES.get(info[2], str(info[2])),
            lower_rad=info[8], upper_rad=info[9], max_force=info[10], max_velocity=info[11],
        )

    # -- control ---------------------------------------------------------------------
    def set_targets_deg(self, targets_deg: Sequence[float]) -> None:
        """Goal angles in degrees for all six actuated joints (arm 0-4, gripper)."""
        goal = np.asarray(targets_deg, dtype=float)
        if goal.shape != (len(ACTUATED_JOINTS),) or not np.all(np.isfinite(goal)):
            raise ValueError(f"expected {len(ACTUATED_JOINTS)} finite angles in degrees, got {targets_deg!r}")
        self._goal_rad = np.radians(goal)

    def targets_deg(self) -> np.ndarray:
        return np.degrees(self._goal_rad)

    def step(self, count: int = 1) -> None:
        """Re-issue the motor targets and advance the physics by `count` time steps."""
        max_delta = self.max_velocity_rad_s * self.time_step_s
        for _ in range(count):
            self._command_rad += np.clip(self._goal_rad - self._command_rad, -max_delta, max_delta)
            p.setJointMotorControlArray(
                self.robot_id, self._indices, p.POSITION_CONTROL,
                targetPositions=self._command_rad.tolist(), forces=self._forces,
                physicsClientId=self.client,
            )
            p.stepSimulation(physicsClientId=self.client)
            self.steps += 1

    # -- state -----------------------------------------------------------------------
    def joint_angles_deg(self) -> np.ndarray:
        """Measured angles in degrees, arm joints 0-4 then the gripper."""
        states = p.getJointStates(self.robot_id, self._indices, physicsClientId=self.client)
        return np.degrees([state[0] for state in states])

    def joint_velocities_deg_s(self) -> np.ndarray:
        states = p.getJointStates(self.robot_id, self._indices, physicsClientId=self.client)
        return np.degrees([state[1] for state in states])

    @property
    def sim_time_s(self) -> float:
        return self.steps * self.time_step_s

    # -- life cycle ------------------------------------------------------------------
    def close(self) -> None:
        """Disconnect; safe to call twice."""
        if self.client is not None and self.client >= 0:
            try:
                p.disconnect(physicsClientId=self.client)
            except p.error:
                pass  # already gone, e.g. the GUI window was closed
        self.client = None

    def __enter__(self) -> "SO101Sim":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
