"""The cameras for headless pictures: the orbiting one (`so101 snapshot`, the simulation's `image`
output, a task's front view) and the one on the gripper (a task's wrist view).

Apart from the simulator so that `so101 snapshot --help` can show its defaults without
loading PyBullet.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Camera:
    """A camera orbiting `target_xyz_m`, in PyBullet's yaw/pitch terms (degrees); `fov_deg` the vertical
    field of view; `roll_deg` turns it about its line of sight (a real camera's tilt; the simulator's are level)."""

    target_xyz_m: tuple[float, float, float] = (0.1, -0.05, 0.12)
    distance_m: float = 0.65
    yaw_deg: float = 35.0
    pitch_deg: float = -25.0
    fov_deg: float = 50.0
    roll_deg: float = 0.0

    def axes(self) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
        """(eye, forward, right, up) in the base's frame, as MuJoCo's free camera draws it (azimuth yaw + 90°,
        elevation pitch), then turned by roll_deg about forward (up toward right when positive)."""
        azimuth, elevation = math.radians(self.yaw_deg + 90.0), math.radians(self.pitch_deg)
        forward = (math.cos(elevation) * math.cos(azimuth), math.cos(elevation) * math.sin(azimuth), math.sin(elevation))
        eye = tuple(t - self.distance_m * f for t, f in zip(self.target_xyz_m, forward))
        level = math.hypot(forward[0], forward[1])
        right = (forward[1] / level, -forward[0] / level, 0.0)  # forward x +z, made unit
        up = cross(right, forward)
        roll = math.radians(self.roll_deg)
        rolled_right = tuple(r * math.cos(roll) - u * math.sin(roll) for r, u in zip(right, up))
        rolled_up = tuple(u * math.cos(roll) + r * math.sin(roll) for r, u in zip(right, up))
        return eye, forward, rolled_right, rolled_up


Vector = tuple[float, float, float]


def cross(a: tuple[float, ...], b: tuple[float, ...]) -> Vector:
    """a x b, for three-number tuples (the camera files' vectors)."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def dot(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def unit(a: tuple[float, ...]) -> Vector:
    length = math.sqrt(dot(a, a))
    return (a[0] / length, a[1] / length, a[2] / length)


def look_at_axes(eye: tuple[float, ...], target: tuple[float, ...], up: tuple[float, ...]) -> tuple[Vector, Vector, Vector]:
    """(right, up, forward) of the picture of a camera at `eye` looking at `target`, unit and square; `up`
    (where the picture's top points) made square to the line of sight, as a camera file's need not be.
    The one place a camera's frame is made from where it stands and looks: camera files, the wrist
    camera's placement and the words that say how to move a camera all take it from here."""
    forward = unit((target[0] - eye[0], target[1] - eye[1], target[2] - eye[2]))
    right = unit(cross(forward, up))
    return right, cross(right, forward), forward


@dataclass(frozen=True)
class WristCamera:
    """A camera fixed to the gripper, in the frame of the URDF's `gripper_link` (the MJCF's body
    `gripper`, the same frame), metres; by default where the SO-101 wrist mount holds it (WRIST_CAMERA)."""

    eye_m: tuple[float, float, float] = (0.0025, 0.0683, -0.0043)
    target_m: tuple[float, float, float] = (0.0025, 0.0260, -0.0949)
    up: tuple[float, float, float] = (0.0, 0.906, -0.423)
    fov_deg: float = 62.0


def wrist_placement(camera: WristCamera) -> tuple[Vector, tuple[float, float, float, float]]:
    """Where MuJoCo puts `camera` on the gripper: its position, and its orientation as a quaternion
    (w, x, y, z) that turns MuJoCo's camera (looking along its -z, its +y up) to look at target_m."""
    eye = camera.eye_m
    right, top, forward = look_at_axes(eye, camera.target_m, camera.up)
    backward = (-forward[0], -forward[1], -forward[2])
    # The rotation's columns are right, top, backward; its quaternion (Shepperd's method, the largest term first).
    m = ((right[0], top[0], backward[0]), (right[1], top[1], backward[1]), (right[2], top[2], backward[2]))
    trace = m[0][0] + m[1][1] + m[2][2]
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        quat = (0.25 * s, (m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s)
    else:
        i = max(range(3), key=lambda k: m[k][k])
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(1.0 + m[i][i] - m[j][j] - m[k][k])
        q = [0.0, 0.0, 0.0]
        q[i], q[j], q[k] = 0.25 * s, (m[j][i] + m[i][j]) / s, (m[k][i] + m[i][k]) / s
        quat = ((m[k][j] - m[j][k]) / s, q[0], q[1], q[2])
    return (eye[0], eye[1], eye[2]), quat


def check_picture(renders: bool, width: int, height: int) -> None:
    """What every body refuses before drawing: no renderer (made with renders=False), or no pixels."""
    if not renders:
        raise RuntimeError("this simulator was made without its renderer (renders=False): no pictures")
    if width < 1 or height < 1:
        raise ValueError(f"image size must be at least 1x1 pixels, got {width}x{height}")


# Frames the whole arm from the front-right and a little above, whether it reaches
# along +x (home) or is panned ±90° toward ∓y.
DEFAULT_CAMERA = Camera()
# What a task's episodes see from the front (observation.images.front): the workspace, not the whole
# arm. A place to reproduce with a tape measure: the lens 38 cm in front of the base's axis (x), 30 cm
# to its right (y) and 46 cm above the table, aimed 50° down at the table 13 cm in front of the base;
# 45° of vertical field of view. The cube's sector and the box fill the picture, and from the front
# right the arm at home hides no cube of the sector (from straight in front it hid 40 of 100).
TASK_FRONT_CAMERA = Camera(target_xyz_m=(0.13, 0.0, 0.0), distance_m=0.60, yaw_deg=40.0, pitch_deg=-50.0, fov_deg=45.0)
# What a task's episodes see from the gripper (observation.images.wrist): where the SO-101 hex-nut
# wrist mount for a 32x32 mm UVC module (SO-ARM100 repository, Optional/SO101_Wrist_Cam_Hex-Nut_Mount_
# 32x32_UVC_Module) holds its camera. That mount screws (two M3, 8.1 mm apart, into the wrist roll
# follower's two hex-nut recesses) onto the follower's flat face at y = +24 mm, with its 3.4 mm pin in
# the servo-screw hole at x = -8.8, z = -13.2 mm. Its camera plate, 4.2 mm thick, holds the board on
# four M2 holes 27 mm apart, centred at x = 2.5, y = 73.3, z = 6.6 mm (the board's face). The lens looks
# through the plate along (0, -0.423, -0.906): tipped 25° from the jaws' -z toward them. The eye is
# put 12 mm along that axis from the board (a guess at where an M12 lens's optics sit, ±5 mm). Up points
# away from the gripper, so the jaws come in from the picture's bottom (the board could be turned in
# 90° steps). 62° vertical field of view: 90° diagonal at 4:3, a wide lens assumed.
WRIST_CAMERA = WristCamera()
# Its name among a MuJoCo model's cameras (a task's scene adds it to the gripper).
WRIST_CAMERA_NAME = "wrist"
