"""Decoding and validating `joint_cmd` messages: plain functions, no dora, no PyBullet.

A `joint_cmd` is a numeric Arrow array in degrees:
  [joint_idx, angle]           one joint (index 0-4 arm, 5 gripper)
  [a0, a1, a2, a3, a4]         all five arm joints (the course's batch)
  [a0, a1, a2, a3, a4, grip]   the arm and the gripper
Any integer or floating width is accepted: `pa.array([1, 45])` arrives as int64,
other nodes send float32.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import pyarrow as pa

from so101.robot import ACTUATED_JOINTS, NUM_ARM_JOINTS

ACCEPTED_FORMS = (
    "accepted: a numeric array in degrees, [joint_idx, angle] with joint_idx 0-5 "
    "(5 = gripper), [a0..a4] or [a0..a4, gripper]"
)


@dataclass
class Decoded:
    """The new targets (degrees, six values) or an error; `notes` lists clamped values."""

    targets_deg: tuple[float, ...] | None = None
    error: str | None = None
    notes: list[str] = field(default_factory=list)
    joint_index: int | None = None  # set for a single-joint command


def _describe(value: object) -> str:
    try:
        if isinstance(value, (pa.Array, pa.ChunkedArray)):
            text = f"{value.type} array of length {len(value)}: {value.to_pylist()!r}"
        else:
            text = f"{type(value).__name__}: {value!r}"
    except Exception:  # noqa: BLE001 - describing must never fail
        text = type(value).__name__
    text = " ".join(text.split())  # a numpy repr spans lines; a log message must not
    return text if len(text) <= 120 else text[:117] + "..."


def clamp_to_limits(joint_position: int, angle_deg: float) -> tuple[float, str | None]:
    """Clamp one angle to its joint's URDF limits; returns (angle, note or None)."""
    joint = ACTUATED_JOINTS[joint_position]
    clamped = joint.clamp_deg(angle_deg)
    if clamped != angle_deg:
        return clamped, f"{joint.name} {angle_deg:g}° is beyond its limits {joint.limits_text()}: clamped to {clamped:.1f}°"
    return angle_deg, None


def decode_joint_cmd(value: object, current_targets_deg: Sequence[float]) -> Decoded:
    """Turn a received `joint_cmd` value into six target angles (degrees), or an error.

    Never raises: whatever arrives, the result is either valid targets inside the
    joint limits or an error message that says what arrived and what is accepted.
    """
    current = tuple(float(angle) for angle in current_targets_deg)
    try:
        if isinstance(value, pa.ChunkedArray):
            value = value.combine_chunks()
        if not isinstance(value, pa.Array):
            return Decoded(error=f"joint_cmd is not an Arrow array ({_describe(value)}); {ACCEPTED_FORMS}")
        kind = value.type
        if not (pa.types.is_integer(kind) or pa.types.is_floating(kind)):
            return Decoded(error=f"joint_cmd has type {kind}, not numeric ({_describe(value)}); {ACCEPTED_FORMS}")
        if value.null_count:
            return Decoded(error=f"joint_cmd has null values ({_describe(value)}); {ACCEPTED_FORMS}")
        numbers = [float(number) for number in value.to_pylist()]
    except Exception as error:  # noqa: BLE001 - a malformed array must not stop the node
        reason = " ".join(f"{type(error).__name__}: {error}".split())
        return Decoded(error=f"joint_cmd could not be read ({reason}); {ACCEPTED_FORMS}")

    if not all(math.isfinite(number) for number in numbers):
        return Decoded(error=f"joint_cmd has NaN or infinite values ({_describe(value)}); {ACCEPTED_FORMS}")

    targets = list(current)
    notes: list[str] = []
    joint_index = None
    if len(numbers) == 2:
        raw_index, angle = numbers
        if raw_index != int(raw_index) or not 0 <= raw_index < len(ACTUATED_JOINTS):
            return Decoded(
                error=f"joint_cmd joint index {raw_index:g} is not an integer from 0 to {len(ACTUATED_JOINTS) - 1} "
                f"({_describe(value)}); {ACCEPTED_FORMS}"
            )
        joint_index = int(raw_index)
        updates = {joint_index: angle}
    elif len(numbers) in (NUM_ARM_JOINTS, len(ACTUATED_JOINTS)):
        updates = dict(enumerate(numbers))
    else:
        return Decoded(error=f"joint_cmd has {len(numbers)} values ({_describe(value)}); {ACCEPTED_FORMS}")

    for position, angle in updates.items():
        clamped, note = clamp_to_limits(position, angle)
        targets[position] = clamped
        if note:
            notes.append(note)
    return Decoded(targets_deg=tuple(targets), notes=notes, joint_index=joint_index)
