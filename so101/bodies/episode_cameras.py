"""Where an episode's cameras stand: the task's own, or its camera files', moved by its looks' jitter
(so101.bodies.looks), and what a dataset keeps of it by episode (its scenario's `cameras`). Pure: no simulator.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from so101.bodies.camera import TASK_FRONT_CAMERA, WRIST_CAMERA, Camera, WristCamera
from so101.bodies.camera_file import CameraFile, front_file_of, orbit_of, wrist_file_of, wrist_of
from so101.bodies.looks import Looks, looks_for


def drawn_front(fixed: Camera, looks: Looks | None) -> Camera:
    """The front camera as an episode's looks place it: `fixed` moved by their jitter (none: as it is)."""
    if looks is None:
        return fixed
    target = tuple(float(a + b) for a, b in zip(fixed.target_xyz_m, looks.front_shift_m))
    return replace(fixed, target_xyz_m=(target[0], target[1], target[2]), yaw_deg=fixed.yaw_deg + looks.front_turn_deg[0],
                   pitch_deg=fixed.pitch_deg + looks.front_turn_deg[1], fov_deg=fixed.fov_deg + looks.front_fov_deg)


def drawn_wrist(fixed: WristCamera, looks: Looks | None) -> WristCamera:
    """The wrist camera as an episode's looks place it: moved within its mount, its aim kept."""
    if looks is None:
        return fixed
    shift = looks.wrist_shift_m
    return WristCamera(tuple(a + b for a, b in zip(fixed.eye_m, shift)),  # type: ignore[arg-type]
                       tuple(a + b for a, b in zip(fixed.target_m, shift)),  # type: ignore[arg-type]
                       fixed.up, fixed.fov_deg + looks.wrist_fov_deg)


def fixed_cameras(poses: dict[str, CameraFile]) -> tuple[Camera, WristCamera]:
    """A task's front and wrist cameras before the looks move them: the files' where given, else the simulator's own."""
    front = orbit_of(poses["front"]) if "front" in poses else TASK_FRONT_CAMERA
    wrist = wrist_of(poses["wrist"]) if "wrist" in poses else WRIST_CAMERA
    return front, wrist


def episode_cameras(poses: dict[str, CameraFile], looks: Looks | None, names: tuple[str, ...],
                    width: int, height: int) -> dict[str, dict[str, Any]]:
    """What a dataset keeps of where an episode's cameras `names` stood (its scenario's `cameras`): each one's
    camera file, as drawn for that episode's looks, at the pictures' size."""
    front, wrist = fixed_cameras(poses)
    kept: dict[str, dict[str, Any]] = {}
    for name in names:
        drawn = (front_file_of(drawn_front(front, looks), width, height) if name == "front"
                 else wrist_file_of(drawn_wrist(wrist, looks), width, height))
        kept[name] = {key: value for key, value in drawn.as_dict().items() if key != "residual_px"}
    return kept


def cameras_metadata(poses: dict[str, CameraFile], looks_mode: str, seed: int, names: tuple[str, ...],
                     size: tuple[int, int]) -> dict[str, object]:
    """episode_cameras for an episode of seed `seed` drawn in `looks_mode` (so101.bodies.looks)."""
    return dict(episode_cameras(poses, looks_for(looks_mode, seed), names, size[0], size[1]))
