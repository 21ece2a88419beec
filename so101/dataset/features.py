"""What a frame of an SO-101 episode holds, as LeRobot's `so101_follower` records it.

LeRobot names each motor's position `<joint>.pos`, in the order of the servo IDs 1-6, which is
this project's `so101.robot.ACTUATED_JOINTS`. The five arm joints are in degrees in both
(LeRobot's `use_degrees`); the gripper is 0-100 in LeRobot (its RANGE_0_100 norm mode) and
−10…100° in the URDF: `to_lerobot` and `from_lerobot` are the one place that maps it.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import numpy.typing as npt

from so101.observe import ALL_OBSERVED, Observed
from so101.robot import ACTUATED_JOINTS, GRIPPER_COMMAND_INDEX

DEFAULT_FPS = 30
ROBOT_TYPE = "so101_follower"
MOTOR_NAMES: tuple[str, ...] = tuple(f"{joint.name}.pos" for joint in ACTUATED_JOINTS)
STATE_KEY = "observation.state"
ACTION_KEY = "action"
IMAGE_KEY = "observation.images.front"
# A task's episodes also see from the gripper (so101.bodies.camera.WRIST_CAMERA).
WRIST_IMAGE_KEY = "observation.images.wrist"
# A task's frames (so101.tasks), named as LeRobot's simulation datasets name them: the objects'
# poses (object_state), whether the task is done after this frame's action, and its reward.
ENVIRONMENT_KEY = "observation.environment_state"
REWARD_KEY = "next.reward"
SUCCESS_KEY = "next.success"
# LeRobot's gripper range, and the URDF's in degrees: its limits, -0.174533 and 1.74533 rad, are
# these to within 0.00002°; mapped on the round values, fully open (100°) is exactly 100.
GRIPPER_RANGE = (0.0, 100.0)
GRIPPER_DEG_RANGE = (-10.0, 100.0)

Float32Array = npt.NDArray[np.float32]
Float64Array = npt.NDArray[np.float64]


def _gripper_scale() -> float:
    return (GRIPPER_RANGE[1] - GRIPPER_RANGE[0]) / (GRIPPER_DEG_RANGE[1] - GRIPPER_DEG_RANGE[0])


def to_lerobot(angles_deg: Sequence[float]) -> Float32Array:
    """Six angles in this project's degrees -> LeRobot's values (float32; the gripper 0-100)."""
    values = np.array(angles_deg, dtype=np.float64)
    if values.shape != (len(ACTUATED_JOINTS),):
        raise ValueError(f"expected {len(ACTUATED_JOINTS)} angles, got shape {values.shape}")
    values[GRIPPER_COMMAND_INDEX] = GRIPPER_RANGE[0] + (values[GRIPPER_COMMAND_INDEX] - GRIPPER_DEG_RANGE[0]) * _gripper_scale()
    return values.astype(np.float32)


def from_lerobot(values: Sequence[float] | npt.NDArray[np.floating]) -> Float64Array:
    """LeRobot's six values (one frame, or an (N, 6) array of them) -> this project's degrees (float64)."""
    angles = np.array(values, dtype=np.float64)
    if angles.shape[-1:] != (len(ACTUATED_JOINTS),):
        raise ValueError(f"expected {len(ACTUATED_JOINTS)} values per frame, got shape {angles.shape}")
    angles[..., GRIPPER_COMMAND_INDEX] = GRIPPER_DEG_RANGE[0] + (angles[..., GRIPPER_COMMAND_INDEX] - GRIPPER_RANGE[0]) / _gripper_scale()
    return angles


def joint_targets_deg(action: Sequence[float] | npt.NDArray[np.floating]) -> list[float]:
    """A policy's action (LeRobot's six values) as the body's six joint targets, in degrees: the policy
    node's joint_cmd, the Gymnasium environment's step (so101.gym)."""
    values = np.asarray(action, dtype=np.float64).reshape(-1)
    if values.shape != (len(ACTUATED_JOINTS),) or not np.all(np.isfinite(values)):
        raise ValueError(f"the policy's action is {values.tolist()}: expected {len(ACTUATED_JOINTS)} finite numbers")
    return [float(angle) for angle in from_lerobot(values)]


def video_keys_and_sizes(image_size: tuple[int, int] | None, task: bool,
                         observed: Observed = ALL_OBSERVED) -> dict[str, tuple[int, int]]:
    """The videos an episode holds, each with its (width, height): the front camera's where there
    are pictures, and with a task the wrist camera's too, the same size, each as far as `observed`
    shows it; {} without pictures."""
    if image_size is None:
        return {}
    return {**({IMAGE_KEY: image_size} if observed.front else {}),
            **({WRIST_IMAGE_KEY: image_size} if task and observed.wrist else {})}
