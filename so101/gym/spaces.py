"""The Gymnasium environment's pure core: its arguments checked, its spaces, an action made into the
body's joint targets, the arm's angles made into `agent_pos`, and what a frame's success means.

Units are LeRobot's SO-101 datasets', as `so101 demos` records them (so101.dataset.features): the
five arm joints in degrees, the gripper 0-100. No simulator is imported here.
"""

from __future__ import annotations

from typing import Any, Callable, Sequence, TypeVar

import numpy as np
import numpy.typing as npt
from gymnasium import spaces

from so101.bodies.backdrop import BackdropError, checked_backdrop
from so101.bodies.camera_file import (
    CameraFile, CameraFileError, camera_file_from, camera_pose_given, read_camera_file, simulated_camera,
)
from so101.bodies.looks import LOOKS_CHOICES
from so101.bodies.physics import physics_mode
from so101.bodies.registry import SIMULATED_BODIES
from so101.dataset.features import joint_targets_deg, to_lerobot
from so101.robot import ACTUATED_JOINTS
from so101.tasks.cube_to_box import CubeToBox

Parsed = TypeVar("Parsed")

OBS_TYPES = ("state", "pixels_agent_pos", "all")
RENDER_MODES = ("rgb_array",)
CAMERA_NAMES = ("front", "wrist")
DEFAULT_CAMERA_SIZE = (320, 240)  # (width, height): so101 demos' pictures (so101.dataset.settings.DEFAULT_IMAGE_SIZE)
# The pictures' sizes `so101 demos --camera-size` takes: even (the videos' encoder needs it), 16 to 4096.
CAMERA_SIZE_RANGE = (16, 4096)
# The observation's bounds: a measured angle passes its joint's limit only pushed, by a few degrees; the
# objects stay within a metre of the base (the arm reaches 0.45 m); a quaternion's parts are within ±1.
JOINT_OVERSHOOT_DEG = 10.0
OBJECT_REACH_M = 1.0
QUATERNION_PARTS = ("qx", "qy", "qz", "qw")

Float32Array = npt.NDArray[np.float32]


def check_choice(name: str, value: object, choices: Sequence[str]) -> str:
    """`value` if it is one of `choices`; ValueError in one line naming them otherwise."""
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name}={value!r} is not one of: {', '.join(repr(choice) for choice in choices)}")
    return value


def check_body(body: object) -> str:
    return check_choice("body", body, SIMULATED_BODIES)


def check_obs_type(obs_type: object) -> str:
    return check_choice("obs_type", obs_type, OBS_TYPES)


def check_looks(looks: object) -> str:
    return check_choice("looks", looks, LOOKS_CHOICES)


def check_physics(physics: object) -> str:
    """`physics`: "fixed", "varied" or a ranges file's path (so101.bodies.physics); ValueError in one line otherwise."""
    if not isinstance(physics, str):
        raise ValueError(f"physics={physics!r} is not one of: 'fixed', 'varied', or a JSON file of ranges")
    try:
        return physics_mode(physics)
    except ValueError as error:
        raise ValueError(f"physics: {error}") from None


def per_camera(option: str, value: object, given: Callable[[str], tuple[str, Parsed]],
               from_map: Callable[[dict], dict[str, Parsed]], error: type[ValueError], each: str) -> dict[str, Parsed]:
    """An option that says something of each camera, as {name: ...} (`from_map` reads it) or the text
    "front=...,wrist=..." (LeRobot's --env.OPTION; `given` reads each part); None or "" for nothing. ValueError in
    one line, naming the option, for a value that is neither or an `error` reading it."""
    if value is None or value == "":
        return {}
    try:
        if isinstance(value, str):
            return dict(given(part.strip()) for part in value.split(","))
        if not isinstance(value, dict):
            raise ValueError(f"{option}={value!r} is not a map from a camera's name to {each}")
        return from_map(value)
    except error as problem:
        raise ValueError(f"{option}: {problem}") from None


def check_camera_pose(camera_pose: object) -> dict[str, CameraFile]:
    """`camera_pose`: where the simulated cameras stand, as {name: camera file's path, or its fields}, or the
    text "front=FILE,wrist=FILE" (LeRobot's --env.camera_pose); None or "" for the simulator's own."""
    return per_camera("camera_pose", camera_pose, camera_pose_given, lambda poses: {
        simulated_camera(name): camera_file_from(given, name) if isinstance(given, dict) else read_camera_file(given, name)
        for name, given in poses.items()}, CameraFileError, "its camera file")


def check_backdrop(backdrop: object) -> dict[str, str]:
    """`backdrop`: photos behind the simulated cameras' scenes, as {name: a photo's or a folder's path}, or the
    text "front=IMAGE[,wrist=IMAGE]" (LeRobot's --env.backdrop); None or "" for none (so101.bodies.backdrop)."""
    return per_camera("backdrop", backdrop, checked_backdrop, lambda photos: dict(
        checked_backdrop(f"{name}={path}") for name, path in photos.items()), BackdropError, "a photo")


def check_render_mode(render_mode: object) -> str | None:
    return None if render_mode is None else check_choice("render_mode", render_mode, RENDER_MODES)


def check_camera_size(camera_size: object) -> tuple[int, int]:
    """(width, height) in even pixels from 16 to 4096, as `so101 demos --camera-size` takes them."""
    low, high = CAMERA_SIZE_RANGE
    sides = tuple(camera_size) if isinstance(camera_size, (tuple, list)) else ()
    if len(sides) != 2 or not all(isinstance(side, (int, np.integer)) and not isinstance(side, bool)
                                  and low <= side <= high and side % 2 == 0 for side in sides):
        raise ValueError(f"camera_size={camera_size!r} is not (width, height) in even pixels from {low} to {high}, "
                         "e.g. (320, 240)")
    return int(sides[0]), int(sides[1])


def sees(obs_type: str) -> bool:
    """Whether an observation of `obs_type` holds the cameras' pictures."""
    return obs_type in ("pixels_agent_pos", "all")


def observes_objects(obs_type: str) -> bool:
    """Whether an observation of `obs_type` holds `environment_state`, the objects' exact poses."""
    return obs_type in ("state", "all")


def action_space() -> spaces.Box:
    """The six joint targets, between the joints' limits (the URDF's, which every driver is held to)."""
    low = to_lerobot([joint.lower_deg for joint in ACTUATED_JOINTS])
    high = to_lerobot([joint.upper_deg for joint in ACTUATED_JOINTS])
    return spaces.Box(low=low, high=high, dtype=np.float32)


def agent_pos_space() -> spaces.Box:
    """The six measured angles: the joints' limits and JOINT_OVERSHOOT_DEG beyond (pushed, a joint passes its limit)."""
    margin = np.array([JOINT_OVERSHOOT_DEG] * len(ACTUATED_JOINTS))
    lower = np.array([joint.lower_deg for joint in ACTUATED_JOINTS])
    upper = np.array([joint.upper_deg for joint in ACTUATED_JOINTS])
    return spaces.Box(low=to_lerobot(lower - margin), high=to_lerobot(upper + margin), dtype=np.float32)


def environment_state_space(object_names: Sequence[str]) -> spaces.Box:
    """The objects' values: a quaternion's within ±1, a position within ±OBJECT_REACH_M of the arm's base."""
    bounds = np.array([1.0 if name.split(".")[-1] in QUATERNION_PARTS else OBJECT_REACH_M for name in object_names],
                      dtype=np.float32)
    return spaces.Box(low=-bounds, high=bounds, dtype=np.float32)


def observation_space(obs_type: str, camera_size: tuple[int, int], object_names: Sequence[str]) -> spaces.Dict:
    """`agent_pos` always; `environment_state` for state and all; `pixels` (front, wrist) for
    pixels_agent_pos and all."""
    width, height = camera_size
    parts: dict[str, spaces.Space[Any]] = {"agent_pos": agent_pos_space()}
    if observes_objects(obs_type):
        parts["environment_state"] = environment_state_space(object_names)
    if sees(obs_type):
        parts["pixels"] = spaces.Dict({name: spaces.Box(0, 255, (height, width, 3), np.uint8) for name in CAMERA_NAMES})
    return spaces.Dict(parts)


def clamped_targets_deg(action: Sequence[float] | npt.NDArray[np.floating]) -> tuple[float, ...]:
    """An action (LeRobot's six values) as six joint targets in degrees, each held within its joint's
    limits as the body node holds a joint_cmd's (so101.joint_cmd); ValueError for any other count or
    a value that is not finite."""
    return tuple(joint.clamp_deg(angle) for joint, angle in zip(ACTUATED_JOINTS, joint_targets_deg(action)))


def agent_pos(angles_deg: Sequence[float]) -> Float32Array:
    """The arm's six measured angles (degrees) as `agent_pos`: LeRobot's `observation.state`."""
    return to_lerobot(angles_deg)


def step_outcome(task: CubeToBox, success: bool) -> tuple[float, bool]:
    """(reward, terminated) of a frame whose success function said `success`: the task's reward (1 where the
    cube is in the box, else 0), and the episode ends at success."""
    return task.reward(success), success
