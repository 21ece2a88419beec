"""What a policy's frames are made of, without LeRobot or torch: which dataflow inputs give each of
its input features, a frame made into LeRobot's observation, and its action made into the body's
joint_cmd. The units are mapped where the recorder maps them (so101.dataset.features): a policy
trained on this project's datasets, or on LeRobot's so101_follower recordings in degrees, sees and
gives the values they hold (degrees; the gripper 0-100); so101.policy.choice refuses one trained in
LeRobot's normalized units. Light: numpy only, so the policy's own
Python (`so101 policy-env`) imports it from the source tree.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from so101.dataset.features import (  # noqa: F401  (joint_targets_deg: the policy node's, named here too)
    ACTION_KEY, ENVIRONMENT_KEY, IMAGE_KEY, MOTOR_NAMES, STATE_KEY, WRIST_IMAGE_KEY, joint_targets_deg, to_lerobot,
)

# Each input feature a policy may declare, and the dataflow inputs that give it.
INPUTS_OF_FEATURE: dict[str, tuple[str, ...]] = {
    STATE_KEY: ("joint_state", "gripper_state"),
    ENVIRONMENT_KEY: ("object_state",),
    IMAGE_KEY: ("image",),
    WRIST_IMAGE_KEY: ("wrist_image",),
}


def inputs_for(input_features: Mapping[str, Sequence[int]], output_features: Mapping[str, Sequence[int]],
               environment_names: Sequence[str], image_size: tuple[int, int] | None) -> tuple[str, ...]:
    """The dataflow inputs a policy with these features (name -> shape) needs, in a fixed order;
    ValueError in one line for a feature the dataflow cannot give, or one of another shape (a
    checkpoint of another robot, another task, other cameras)."""
    expected: dict[str, tuple[int, ...]] = {STATE_KEY: (len(MOTOR_NAMES),), ENVIRONMENT_KEY: (len(environment_names),)}
    if image_size is not None:
        width, height = image_size
        expected[IMAGE_KEY] = expected[WRIST_IMAGE_KEY] = (3, height, width)
    needed: list[str] = []
    for name, shape in input_features.items():
        if name not in INPUTS_OF_FEATURE:
            raise ValueError(f"the policy asks for {name}, which this dataflow cannot give (it gives "
                             f"{', '.join(INPUTS_OF_FEATURE)})")
        if name not in expected:
            raise ValueError(f"the policy asks for {name}, and this dataflow has no pictures: run it with cameras")
        if tuple(shape) != expected[name]:
            raise ValueError(f"the policy's {name} has shape {tuple(shape)}, this dataflow's {expected[name]}: "
                             "it was trained on another robot, task or picture size")
        needed.extend(INPUTS_OF_FEATURE[name])
    action = tuple(output_features.get(ACTION_KEY, ()))
    if action != (len(MOTOR_NAMES),):
        raise ValueError(f"the policy's {ACTION_KEY} has shape {action or 'none'}, the SO-101's is ({len(MOTOR_NAMES)},)")
    return tuple(input_id for input_id in (*INPUTS_OF_FEATURE[STATE_KEY], "object_state", "image", "wrist_image")
                 if input_id in needed)


def observation(frame: Mapping[str, Any], image_size: tuple[int, int] | None) -> dict[str, np.ndarray]:
    """A frame's inputs (name -> list of numbers, or a picture's flat bytes) as LeRobot's observation:
    float32 state and environment, HxWx3 uint8 pictures (LeRobot's own inference makes them
    channels-first floats)."""
    values: dict[str, np.ndarray] = {}
    if "joint_state" in frame:
        values[STATE_KEY] = to_lerobot([*frame["joint_state"], *frame["gripper_state"]])
    if "object_state" in frame:
        values[ENVIRONMENT_KEY] = np.asarray(frame["object_state"], dtype=np.float32)
    for input_id, key in (("image", IMAGE_KEY), ("wrist_image", WRIST_IMAGE_KEY)):
        if input_id in frame and image_size is not None:
            width, height = image_size
            # A copy: arrow's buffers are read-only, and torch warns of every one it is given.
            values[key] = np.array(frame[input_id], dtype=np.uint8).reshape(height, width, 3)
    return values


def read_policy_features(folder: Path) -> tuple[dict[str, tuple[int, ...]], dict[str, tuple[int, ...]]]:
    """(input features, output features), name -> shape, from a policy folder's config.json as LeRobot
    writes it, without loading LeRobot; ValueError in one line for a folder that is not a policy's."""
    config_file = folder / "config.json"
    if not folder.is_dir():
        raise ValueError(f"{folder} is not a folder: give a trained policy's folder (.../checkpoints/last/pretrained_model)")
    try:
        config = json.loads(config_file.read_text(encoding="utf-8"))
        inputs, outputs = ({name: tuple(int(size) for size in feature["shape"]) for name, feature in config[key].items()}
                           for key in ("input_features", "output_features"))
        return inputs, outputs
    except FileNotFoundError:
        raise ValueError(f"{folder} has no config.json: it is not a policy folder as lerobot-train writes it "
                         "(.../checkpoints/last/pretrained_model)") from None
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as error:
        raise ValueError(f"{config_file} is not a LeRobot policy's config ({type(error).__name__}: {error})") from None


def picture_size_of(input_features: Mapping[str, Sequence[int]]) -> tuple[int, int] | None:
    """The (width, height) of the pictures a policy sees (channels first, as LeRobot declares them), or None."""
    for name in (IMAGE_KEY, WRIST_IMAGE_KEY):
        if name in input_features and len(input_features[name]) == 3:
            _, height, width = input_features[name]
            return int(width), int(height)
    return None


def unscaled_inputs(folder: Path) -> dict[str, str]:
    """The numeric input features (state, environment) a policy folder's config.json leaves unscaled,
    name -> type: their type has no normalization in its `normalization_mapping`, or IDENTITY. LeRobot 0.4.4's ACT
    maps VISUAL, STATE and ACTION only, so by default `observation.environment_state` (the cube's
    place, in metres: a spread of centimetres) reaches its network as it is, beside joints scaled to a
    spread of 1. Call after read_policy_features has accepted the folder."""
    config = json.loads((folder / "config.json").read_text(encoding="utf-8"))
    mapping = config.get("normalization_mapping") or {}
    return {name: feature["type"] for name, feature in config["input_features"].items()
            if feature.get("type") in ("STATE", "ENV") and mapping.get(feature["type"], "IDENTITY") == "IDENTITY"}
