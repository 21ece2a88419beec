"""Saved poses (exercise 1's `save NAME` / `go NAME`), kept in a JSON file that survives restarts.

The file maps each name to its angles in degrees:
    {"a": {"joints_deg": [-30.0, 45.0, -60.0, 30.0, 0.0], "gripper_deg": 0.0}}
`gripper_deg` may be null (no gripper_state had arrived when the pose was saved).

Every save rewrites the whole file through a temporary file and os.replace, so a
crash mid-write leaves the previous file, never half a file. A file that cannot
be read or does not hold poses is moved aside (renamed with a `.corrupt-<time>`
suffix) and reported, never silently overwritten.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from so101.robot import NUM_ARM_JOINTS


@dataclass(frozen=True)
class Pose:
    joints_deg: tuple[float, ...]  # the five arm joints
    gripper_deg: float | None = None

    def joint_cmd_deg(self) -> tuple[float, ...]:
        """The batch that moves to this pose: five values, or six with the gripper."""
        return self.joints_deg if self.gripper_deg is None else self.joints_deg + (self.gripper_deg,)


class PosesFileError(ValueError):
    """The poses file exists but does not hold valid poses."""


def _finite(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def poses_from_json(data: object) -> dict[str, Pose]:
    """The decoded JSON document -> poses; raises PosesFileError saying what is wrong."""
    if not isinstance(data, dict):
        raise PosesFileError(f"expected a JSON object of poses, found {type(data).__name__}")
    poses = {}
    for name, entry in data.items():
        joints = entry.get("joints_deg") if isinstance(entry, dict) else None
        if not (isinstance(joints, list) and len(joints) == NUM_ARM_JOINTS and all(map(_finite, joints))):
            raise PosesFileError(f"pose {name!r} has no list of {NUM_ARM_JOINTS} finite numbers under 'joints_deg'")
        gripper = entry.get("gripper_deg")
        if gripper is not None and not _finite(gripper):
            raise PosesFileError(f"pose {name!r} has a 'gripper_deg' that is not a finite number")
        poses[name] = Pose(tuple(float(angle) for angle in joints), None if gripper is None else float(gripper))
    return poses


def poses_to_json(poses: dict[str, Pose]) -> dict:
    return {
        name: {"joints_deg": list(pose.joints_deg), "gripper_deg": pose.gripper_deg}
        for name, pose in poses.items()
    }


class PoseStore:
    """Named poses backed by a JSON file. `load_notice` is the one-line report of a bad file, or None."""

    def __init__(self, path: Path | str):
        self.path = Path(path)
        self.poses: dict[str, Pose] = {}
        self.load_notice: str | None = None
        # False when a bad file could not be moved aside: writing would destroy it.
        self.writable = True
        self._load()

    def _load(self) -> None:
        try:
            raw = self.path.read_bytes()
        except FileNotFoundError:
            return
        except OSError as error:
            problem = f"cannot be read ({error.strerror or error})"
        else:
            try:
                self.poses = poses_from_json(json.loads(raw.decode("utf-8")))
                return
            except (UnicodeDecodeError, json.JSONDecodeError, PosesFileError) as error:
                problem = f"is not a valid poses file ({error})"
        aside = self.path.with_name(f"{self.path.name}.corrupt-{time.strftime('%Y%m%d-%H%M%S')}")
        try:
            os.replace(self.path, aside)
            self.load_notice = f"poses file {self.path} {problem}: moved aside to {aside.name}, starting with no saved poses"
        except OSError as error:
            self.writable = False
            self.load_notice = (
                f"poses file {self.path} {problem} and could not be moved aside ({error.strerror or error}): "
                "saved poses are kept for this run only, the file is left as it is"
            )

    def names(self) -> list[str]:
        return sorted(self.poses)

    def get(self, name: str) -> Pose | None:
        return self.poses.get(name)

    def save(self, name: str, pose: Pose) -> str | None:
        """Store the pose and write the file; returns None, or why the file could not be written
        (the pose is kept in memory either way)."""
        self.poses[name] = pose
        if not self.writable:
            return f"{self.path} was unreadable at start and is left untouched"
        try:
            self._write()
        except OSError as error:
            return f"{self.path}: {error.strerror or error}"
        return None

    def _write(self) -> None:
        text = json.dumps(poses_to_json(self.poses), ensure_ascii=False, indent=2) + "\n"
        self.path.parent.mkdir(parents=True, exist_ok=True)
        handle, temporary = tempfile.mkstemp(prefix=f".{self.path.name}.", suffix=".tmp", dir=self.path.parent)
        try:
            with os.fdopen(handle, "w", encoding="utf-8") as stream:
                stream.write(text)
                stream.flush()
                os.fsync(stream.fileno())
            os.replace(temporary, self.path)
        except BaseException:
            try:
                os.unlink(temporary)
            except OSError:
                pass
            raise
