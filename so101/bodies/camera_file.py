"""Camera files: where a camera stands, as JSON a person can read, edit and measure.

`so101 cameras --default NAME` prints one, `so101 cameras --fit NAME` writes one, and
`--camera-pose NAME=FILE` draws a task's camera from one. The fields:

- `camera`: "front" (fixed in the base's frame) or "wrist" (fixed to the gripper, in its frame:
  the URDF's `gripper_link`, the MJCF's body `gripper`);
- `frame`: "base" or "gripper", which frame the three vectors are in (the camera's own);
- `position_m`: the lens's centre; `look_at_m`: a point it looks at; `up`: which way the picture's
  top points (need not be exactly square to the line of sight);
- `fov_deg`: the vertical field of view; `width`, `height`: the picture's size in pixels;
- `residual_px` (a fit's): how far, in pixels at that size, the fitted arm's outline lies from the
  pictures' on average; null for a camera that was not fitted.

A pinhole: the principal point at the picture's centre, no lens distortion. Pure: no simulator.
Here the format, its checks, and the files as the renderer's cameras (so101.bodies.camera); where an
episode's looks move them, and what a dataset keeps of it: so101.bodies.episode_cameras.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from so101.bodies.camera import TASK_FRONT_CAMERA, WRIST_CAMERA, Camera, Vector, WristCamera, cross, dot, look_at_axes

CAMERA_NAMES = ("front", "wrist")
FRAMES = {"front": "base", "wrist": "gripper"}
# The size a camera file says when none is given: the task's pictures' default (so101 demos).
DEFAULT_SIZE = (320, 240)
# A line of sight closer than this to vertical has no yaw: the front camera must be tilted at least this far.
LEVEL_MIN_DEG = 1.0


class CameraFileError(ValueError):
    """A camera file that cannot be used; str() is one line that says what is wrong."""


@dataclass(frozen=True)
class CameraFile:
    camera: str
    position_m: Vector
    look_at_m: Vector
    up: Vector
    fov_deg: float
    width: int = DEFAULT_SIZE[0]
    height: int = DEFAULT_SIZE[1]
    residual_px: float | None = None

    @property
    def frame(self) -> str:
        return FRAMES[self.camera]

    def as_dict(self) -> dict[str, Any]:
        return {"camera": self.camera, "frame": self.frame, "position_m": [round(v, 6) for v in self.position_m],
                "look_at_m": [round(v, 6) for v in self.look_at_m], "up": [round(v, 6) for v in self.up],
                "fov_deg": round(self.fov_deg, 4), "width": self.width, "height": self.height,
                "residual_px": None if self.residual_px is None else round(self.residual_px, 4)}

    def as_json(self) -> str:
        """The file's text: a field a line, each vector on its line."""
        lines = [f"  {json.dumps(key)}: {json.dumps(value)}" for key, value in self.as_dict().items()]
        return "{\n" + ",\n".join(lines) + "\n}\n"


def _vector(fields: dict[str, Any], key: str) -> Vector:
    value = fields.get(key)
    if (not isinstance(value, (list, tuple)) or len(value) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)):
        raise CameraFileError(f"`{key}` must be three numbers (metres in the camera's frame), got {value!r}")
    return (float(value[0]), float(value[1]), float(value[2]))


def _norm(vector: tuple[float, ...]) -> float:
    return math.sqrt(sum(v * v for v in vector))


def camera_file_from(fields: object, name: str | None = None) -> CameraFile:
    """A camera file's fields (its parsed JSON) checked; CameraFileError in one line otherwise. `name`:
    the camera the file must be for (the NAME of `--camera-pose NAME=FILE`)."""
    if not isinstance(fields, dict):
        raise CameraFileError("a camera file is a JSON object with camera, position_m, look_at_m, up, fov_deg, width, height")
    camera = fields.get("camera", name)
    if camera not in CAMERA_NAMES:
        raise CameraFileError(f"`camera` must be one of {', '.join(CAMERA_NAMES)}, got {camera!r}")
    if name is not None and camera != name:
        raise CameraFileError(f"this file is the {camera} camera's, not the {name} camera's")
    frame = fields.get("frame", FRAMES[camera])
    if frame != FRAMES[camera]:
        raise CameraFileError(f"the {camera} camera's vectors are in the {FRAMES[camera]} frame, not {frame!r}")
    position, look_at, up = _vector(fields, "position_m"), _vector(fields, "look_at_m"), _vector(fields, "up")
    sight = tuple(b - a for a, b in zip(position, look_at))
    if _norm(sight) < 1e-3:
        raise CameraFileError("`look_at_m` must be at least 1 mm from `position_m`: they give the line of sight")
    across = cross(up, sight)
    if _norm(up) < 1e-9 or _norm(across) < 1e-3 * _norm(up) * _norm(sight):
        raise CameraFileError("`up` must not be zero nor along the line of sight (position_m to look_at_m)")
    if camera == "front" and abs(sight[2]) / _norm(sight) > math.cos(math.radians(LEVEL_MIN_DEG)):
        raise CameraFileError(f"the front camera looks straight up or down: tilt its line of sight at least {LEVEL_MIN_DEG:g}°")
    fov = fields.get("fov_deg")
    if isinstance(fov, bool) or not isinstance(fov, (int, float)) or not 1.0 <= fov <= 170.0:
        raise CameraFileError(f"`fov_deg` (the vertical field of view) must be a number of degrees from 1 to 170, got {fov!r}")
    size = []
    for key, default in (("width", DEFAULT_SIZE[0]), ("height", DEFAULT_SIZE[1])):
        value = fields.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 8192:
            raise CameraFileError(f"`{key}` must be a whole number of pixels from 1 to 8192, got {value!r}")
        size.append(value)
    residual = fields.get("residual_px")
    if residual is not None and (isinstance(residual, bool) or not isinstance(residual, (int, float)) or residual < 0):
        raise CameraFileError(f"`residual_px` must be null or a number >= 0, got {residual!r}")
    return CameraFile(str(camera), position, look_at, up, float(fov), size[0], size[1],
                      None if residual is None else float(residual))


def read_camera_file(path: Path | str, name: str | None = None) -> CameraFile:
    """The camera file at `path`; CameraFileError in one line, naming the file, for anything else."""
    try:
        text = Path(path).expanduser().read_text(encoding="utf-8")
    except OSError as error:
        raise CameraFileError(f"{path}: cannot be read ({error.strerror or error})") from None
    try:
        fields = json.loads(text)
    except json.JSONDecodeError as error:
        raise CameraFileError(f"{path}: not a camera file: not JSON ({error.msg}, line {error.lineno})") from None
    try:
        return camera_file_from(fields, name)
    except CameraFileError as error:
        raise CameraFileError(f"{path}: {error}") from None


def orbit_of(front: CameraFile) -> Camera:
    """The front camera file as the renderer's orbiting camera (its look_at the target, its up a roll)."""
    eye, target = front.position_m, front.look_at_m
    _, square_up, forward = look_at_axes(eye, target, front.up)
    level = Camera(target, _norm(tuple(b - a for a, b in zip(eye, target))),
                   math.degrees(math.atan2(forward[1], forward[0])) - 90.0,
                   math.degrees(math.asin(max(-1.0, min(1.0, forward[2])))), front.fov_deg)
    # The roll: how far the file's up is turned from the level camera's, about the line of sight.
    _, _, right, up = level.axes()
    roll = math.degrees(math.atan2(dot(square_up, right), dot(square_up, up)))
    return replace(level, yaw_deg=(level.yaw_deg + 180.0) % 360.0 - 180.0, roll_deg=roll)


def front_file_of(camera: Camera, width: int, height: int, residual_px: float | None = None) -> CameraFile:
    """The orbiting `camera` as the front camera's file, for pictures of `width` x `height`."""
    eye, _, _, up = camera.axes()
    return CameraFile("front", (eye[0], eye[1], eye[2]), camera.target_xyz_m, (up[0], up[1], up[2]), camera.fov_deg,
                      width, height, residual_px)


def wrist_of(wrist: CameraFile) -> WristCamera:
    return WristCamera(wrist.position_m, wrist.look_at_m, wrist.up, wrist.fov_deg)


def wrist_file_of(camera: WristCamera, width: int, height: int, residual_px: float | None = None) -> CameraFile:
    return CameraFile("wrist", camera.eye_m, camera.target_m, camera.up, camera.fov_deg, width, height, residual_px)


def simulated_camera(name: object) -> str:
    """`name` if it is a simulated camera's; CameraFileError in one line otherwise."""
    if name not in CAMERA_NAMES:
        raise CameraFileError(f"unknown camera {name!r}; the simulated ones are: {', '.join(CAMERA_NAMES)}")
    return str(name)


def camera_pose_given(text: str) -> tuple[str, CameraFile]:
    """NAME=FILE (`--camera-pose`, so101.gym's camera_pose): the camera's name and its file, read and checked."""
    name, equals, path = text.partition("=")
    if not equals or not name or not path:
        raise CameraFileError(f"{text!r} is not NAME=FILE (e.g. front=my_front.json)")
    return simulated_camera(name), read_camera_file(path, name)


def default_camera_file(name: str, width: int = DEFAULT_SIZE[0], height: int = DEFAULT_SIZE[1]) -> CameraFile:
    """The simulated camera `name`'s own file: where a task's episodes draw it from (without varied looks)."""
    if simulated_camera(name) == "front":
        return front_file_of(TASK_FRONT_CAMERA, width, height)
    return wrist_file_of(WRIST_CAMERA, width, height)


def parse_camera_poses(text: str) -> dict[str, CameraFile]:
    """A scenario's camera poses (so101.bodies.scenario): JSON mapping a camera's name to its file's fields ("" none)."""
    if not text.strip():
        return {}
    try:
        fields = json.loads(text)
    except json.JSONDecodeError as error:
        raise CameraFileError(f"not JSON ({error.msg})") from None
    if not isinstance(fields, dict):
        raise CameraFileError("a JSON object mapping a camera's name to its camera file's fields")
    return {name: camera_file_from(value, str(name)) for name, value in fields.items()}
