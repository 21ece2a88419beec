"""`so101 snapshot`: the arm in a given pose, rendered headless to a PNG.

No window and no GPU: DIRECT mode and PyBullet's CPU renderer. `--task NAME [--seed N]` puts the
task's scene on the floor, laid out from the seed; `--camera wrist` draws from the camera on the
gripper that a task's episodes record.

`--axes` draws the base frame (the URDF's base_link, the simulation's world origin: x forward,
y to the arm's left, z up, the floor at z = 0) over the finished picture: each point is
projected with the view and projection the render used (PyBullet's yaw/pitch/distance
matrices; MuJoCo's scene camera), and Pillow draws the lines and labels on top. It is an
overlay: the arm does not hide an axis that runs behind it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np

from so101.bodies.registry import BODIES, DEFAULT_BODY, SIMULATED_BODIES
from so101.runtime.dataflow import TICK_PERIOD_S
from so101.robot import ACTUATED_JOINTS, HOME_POSE_DEG, NUM_ARM_JOINTS

REACHED_TOLERANCE_DEG = 0.5
STILL_DEG_S = 0.5
SETTLE_BUDGET_S = 5.0
MAX_IMAGE_SIDE_PX = 4096

AXIS_LENGTH_MM = 200.0
AXIS_TICK_MM = 100.0  # a tick across each axis every this far from the origin
# (direction in the base frame, colour, label at the end). Saturated colours that neither
# floor (white and pale blue) nor arm (yellow) has, so the lines stand out and tests find them.
AXES = (
    ((1.0, 0.0, 0.0), (230, 0, 0), "x forward"),
    ((0.0, 1.0, 0.0), (0, 170, 0), "y left"),
    ((0.0, 0.0, 1.0), (0, 60, 255), "z up"),
)
# Points nearer the camera than this (metres along its view) are cut off a line: behind the
# camera a perspective projection flips them to the wrong side of the picture.
NEAR_M = 0.01
# The near and far planes PyBullet's render uses (SO101Sim.render_rgb); they change depth only,
# not where a point lands in the picture.
PYBULLET_NEAR_FAR_M = (0.01, 10.0)


def _image_side(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 16 <= value <= MAX_IMAGE_SIDE_PX:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of pixels from 16 to {MAX_IMAGE_SIDE_PX}")
    return value


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    from so101.bodies.camera import DEFAULT_CAMERA
    from so101.bodies.looks import DEFAULT_LOOKS, LOOKS_CHOICES

    parser.add_argument(
        "--body", choices=SIMULATED_BODIES, default=DEFAULT_BODY,
        help="which simulator drives the arm to the pose and draws it: pybullet (default, its CPU renderer) "
        "or mujoco (offscreen through EGL where there is no display)",
    )
    parser.add_argument(
        "--pose", type=float, nargs="+", metavar="DEG", default=None,
        help="joint angles in degrees: a0 a1 a2 a3 a4, optionally the gripper as a sixth (default: home, all 0)",
    )
    parser.add_argument("--out", type=Path, default=Path("out/snapshot.png"), help="PNG to write (default out/snapshot.png)")
    parser.add_argument("--width", type=_image_side, default=640, help="image width in pixels (default 640)")
    parser.add_argument("--height", type=_image_side, default=480, help="image height in pixels (default 480)")
    parser.add_argument("--yaw", type=float, default=DEFAULT_CAMERA.yaw_deg, help="camera yaw in degrees (default %(default)s)")
    parser.add_argument("--pitch", type=float, default=DEFAULT_CAMERA.pitch_deg, help="camera pitch in degrees (default %(default)s)")
    parser.add_argument(
        "--distance", type=float, default=DEFAULT_CAMERA.distance_m, help="camera distance in metres (default %(default)s)",
    )
    from so101.launch.beside_prompt import add_task_arguments

    add_task_arguments(parser)
    parser.add_argument(
        "--camera", choices=("front", "wrist"), default="front",
        help="front: the orbiting camera (--yaw, --pitch, --distance); wrist: the camera on the gripper, which a "
        "task's episodes record (needs --task)",
    )
    parser.add_argument(
        "--looks", choices=LOOKS_CHOICES, default=DEFAULT_LOOKS,
        help="--task: varied draws the task's cameras as an episode of --seed records them with `--looks varied` "
        "(that seed's light, colours and camera placement; --yaw, --pitch and --distance do not apply); unseen: "
        "the held-out looks (beyond varied's palettes and spreads); fixed (default): as always",
    )
    parser.add_argument(
        "--axes", action="store_true",
        help=f"draw the arm's base frame (the URDF's base_link, the frame of the prompt's xyz and where) from its "
        f"origin on the floor under the base: x forward (red), y to the arm's left (green), z up (blue), "
        f"{AXIS_LENGTH_MM:g} mm each with a tick every {AXIS_TICK_MM:g} mm, labelled at their ends; an overlay "
        "drawn on the finished picture, so it shows over the arm, not hidden by it",
    )


def pose_error(pose_deg: list[float] | None) -> str | None:
    """Why a --pose is not acceptable, or None."""
    if pose_deg is None:
        return None
    if len(pose_deg) not in (NUM_ARM_JOINTS, NUM_ARM_JOINTS + 1):
        return f"--pose takes {NUM_ARM_JOINTS} angles (joints 0-4) or {NUM_ARM_JOINTS + 1} (with the gripper), got {len(pose_deg)}"
    for position, (angle, joint) in enumerate(zip(pose_deg, ACTUATED_JOINTS)):
        if not joint.allows_deg(angle):
            return f"--pose angle {position} ({joint.name}) is {angle:g}°, outside its range {joint.limits_text()}"
    return None


class Projector(NamedTuple):
    """Base-frame points to pixels: `matrix` (projection @ view, row-major 4x4) takes metres to
    OpenGL clip coordinates; the picture is `width` x `height`, row 0 at the top."""

    matrix: np.ndarray
    width: int
    height: int

    def clip(self, points_mm) -> np.ndarray:
        """Clip coordinates (x, y, z, w) of points in mm, shape (N, 4); w is the depth in metres."""
        points_m = np.atleast_2d(np.asarray(points_mm, dtype=float)) / 1000.0
        return np.hstack([points_m, np.ones((len(points_m), 1))]) @ self.matrix.T

    def pixels_from_clip(self, clip: np.ndarray) -> np.ndarray:
        ndc = clip[:, :2] / clip[:, 3:4]
        return np.column_stack([(ndc[:, 0] + 1.0) * 0.5 * self.width, (1.0 - ndc[:, 1]) * 0.5 * self.height])

    def pixels(self, points_mm) -> np.ndarray:
        """(column, row) of points in mm, shape (N, 2), as floats; NaN for a point behind the camera."""
        clip = self.clip(points_mm)
        pixels = self.pixels_from_clip(clip)
        pixels[clip[:, 3] < NEAR_M] = np.nan
        return pixels

    def segment(self, start_mm, end_mm) -> tuple[np.ndarray, np.ndarray] | None:
        """The pixel ends of the part of a 3D line in front of the camera, or None if none is."""
        (a, b) = self.clip([start_mm, end_mm])
        if a[3] < NEAR_M and b[3] < NEAR_M:
            return None
        if a[3] < NEAR_M or b[3] < NEAR_M:
            cut = a + (b - a) * (NEAR_M - a[3]) / (b[3] - a[3])
            a, b = (cut, b) if a[3] < NEAR_M else (a, cut)
        start, end = self.pixels_from_clip(np.vstack([a, b]))
        return start, end


def _column_major(values) -> np.ndarray:
    return np.asarray(values, dtype=float).reshape(4, 4).T


def pybullet_projector(camera, width: int, height: int) -> Projector:
    """The projection of SO101Sim.render_rgb: the same calls with the same arguments (pure
    functions: no client needed). PyBullet gives its matrices column-major."""
    import pybullet as p

    view = p.computeViewMatrixFromYawPitchRoll(
        cameraTargetPosition=list(camera.target_xyz_m), distance=camera.distance_m,
        yaw=camera.yaw_deg, pitch=camera.pitch_deg, roll=0.0, upAxisIndex=2,
    )
    near_m, far_m = PYBULLET_NEAR_FAR_M
    projection = p.computeProjectionMatrixFOV(fov=camera.fov_deg, aspect=width / height, nearVal=near_m, farVal=far_m)
    return Projector(_column_major(projection) @ _column_major(view), width, height)


def mujoco_projector(sim, width: int, height: int) -> Projector:
    """The camera of the MuJoCo picture just drawn: its renderer's scene, as mjr_render uses it
    (the average of the two stereo cameras; the frustum's width from the picture's aspect)."""
    import mujoco

    scene = sim.drawn_scene()
    camera = mujoco.mjv_averageCamera(scene.camera[0], scene.camera[1])
    forward, up, position = (np.asarray(vector, dtype=float) for vector in (camera.forward, camera.up, camera.pos))
    right = np.cross(forward, up)
    view = np.eye(4)
    view[:3, :3] = np.vstack([right, up, -forward])
    view[:3, 3] = -view[:3, :3] @ position
    near, far = camera.frustum_near, camera.frustum_far
    bottom, top = camera.frustum_bottom, camera.frustum_top
    half_width = camera.frustum_width or 0.5 * (width / height) * (top - bottom)
    left, right_edge = camera.frustum_center - half_width, camera.frustum_center + half_width
    projection = np.array([  # glFrustum
        [2 * near / (right_edge - left), 0, (right_edge + left) / (right_edge - left), 0],
        [0, 2 * near / (top - bottom), (top + bottom) / (top - bottom), 0],
        [0, 0, -(far + near) / (far - near), -2 * far * near / (far - near)],
        [0, 0, -1, 0],
    ])
    return Projector(projection @ view, width, height)


def draw_axes(image, projector: Projector) -> None:
    """The base frame's axes on `image` (a Pillow RGB image), in place: lines, ticks, labels."""
    from PIL import ImageDraw, ImageFont

    draw = ImageDraw.Draw(image)
    side = min(projector.width, projector.height)
    line_px = max(2, round(side / 160))
    font = ImageFont.load_default(size=max(10, round(side / 24)))
    small_font = ImageFont.load_default(size=max(8, round(side / 34)))
    stroke_px = max(1, round(side / 240))
    tick_px = max(3, round(side / 80))
    origin = np.zeros(3)
    labels = []
    for axis, colour, label in AXES:
        direction = np.asarray(axis)
        end_mm = direction * AXIS_LENGTH_MM
        segment = projector.segment(origin, end_mm)
        if segment is None:
            continue
        start, end = segment
        draw.line([tuple(start), tuple(end)], fill=colour, width=line_px)
        along = end - start
        if not np.hypot(*along) > 0:
            continue  # the axis points straight at the camera
        along = along / np.hypot(*along)
        across = np.array([-along[1], along[0]])
        distance_mm = AXIS_TICK_MM
        while distance_mm < AXIS_LENGTH_MM:
            (tick,) = projector.pixels([direction * distance_mm])
            if not np.isnan(tick).any():
                draw.line([tuple(tick - across * tick_px), tuple(tick + across * tick_px)], fill=colour, width=line_px)
                labels.append((tick + across * (tick_px + 2), across, f"{distance_mm:g}", colour, small_font))
            distance_mm += AXIS_TICK_MM
        labels.append((end + along * 4, along, label, colour, font))
    for at, away, text, colour, label_font in labels:
        # Beside the point, on the side `away` points to: the box's centre is moved out by
        # half its extent along that direction, so no corner of it covers the point.
        left, top, right, bottom = draw.textbbox((0, 0), text, font=label_font, stroke_width=stroke_px)
        centre = at + away * (abs(away[0]) * (right - left) / 2 + abs(away[1]) * (bottom - top) / 2)
        draw.text(
            tuple(centre), text, font=label_font, fill=colour, anchor="mm", stroke_width=stroke_px, stroke_fill="white",
        )


def run(args: argparse.Namespace) -> int:
    from PIL import Image

    from so101.bodies.camera import DEFAULT_CAMERA, WRIST_CAMERA, Camera
    from so101.tasks import task_named

    error = pose_error(args.pose)
    if not args.distance > 0:
        error = f"--distance must be a positive number of metres, got {args.distance:g}"
    elif args.seed is not None and args.task is None:
        error = "--seed goes with --task NAME"
    elif args.camera == "wrist" and args.task is None:
        error = "--camera wrist is a task's camera: add --task cube_to_box"
    elif args.camera == "wrist" and args.axes:
        error = "--axes is drawn for the front camera only"
    elif args.looks != "fixed" and args.task is None:
        error = f"--looks {args.looks} is a task's cameras': add --task cube_to_box"
    elif args.looks != "fixed" and args.axes:
        error = f"--axes is drawn on the orbiting camera's picture, not with --looks {args.looks}"
    if error:
        print(f"so101 snapshot: {error}", file=sys.stderr)
        return 2
    targets_deg = list(HOME_POSE_DEG)
    if args.pose is not None:
        targets_deg[: len(args.pose)] = args.pose
    camera = Camera(
        target_xyz_m=DEFAULT_CAMERA.target_xyz_m, distance_m=args.distance,
        yaw_deg=args.yaw, pitch_deg=args.pitch, fov_deg=DEFAULT_CAMERA.fov_deg,
    )
    simulator = BODIES[args.body].body_class()
    task = task_named(args.task) if args.task else None
    with simulator(mode="direct", time_step_s=TICK_PERIOD_S, log=lambda message: None, task=task,
                   seed=args.seed or 0) as sim:
        sim.set_targets_deg(targets_deg)
        for _ in range(round(SETTLE_BUDGET_S / TICK_PERIOD_S)):
            sim.step()
            # Reached and still: a picture mid-swing would not show the asked pose.
            if (
                np.all(np.abs(sim.joint_angles_deg() - targets_deg) < REACHED_TOLERANCE_DEG)
                and np.all(np.abs(sim.joint_velocities_deg_s()) < STILL_DEG_S)
            ):
                break
        reached_deg = sim.joint_angles_deg()
        if args.looks != "fixed":  # drawn as an episode's cameras draw it (so101.bodies.task_cameras)
            from so101.bodies.task_cameras import TaskCameras

            with TaskCameras(task, log=lambda message: None, looks=args.looks) as cameras:
                cameras.show_seed(args.seed or 0)
                front, wrist = cameras.draw(reached_deg, sim.scene.object_state(), args.width, args.height)
            rgb = wrist if args.camera == "wrist" and wrist is not None else front
        else:
            rgb = sim.render_rgb(args.width, args.height, WRIST_CAMERA if args.camera == "wrist" else camera)
        image = Image.fromarray(rgb)
        if args.axes:
            if args.body == "mujoco":
                projector = mujoco_projector(sim, args.width, args.height)
            else:
                projector = pybullet_projector(camera, args.width, args.height)
            draw_axes(image, projector)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    # A PNG whatever the name ends in, as before: by default Pillow picks the format from the suffix
    # and fails on one it does not know (`--out arm`).
    image.save(args.out, format="PNG")
    angles = " ".join(f"{angle:.1f}" for angle in reached_deg)
    print(f"wrote {args.out} ({args.width}x{args.height}), pose reached (deg, joints 0-4 and gripper): {angles}")
    missed = np.abs(reached_deg - targets_deg) >= REACHED_TOLERANCE_DEG
    if missed.any():
        names = ", ".join(ACTUATED_JOINTS[i].name for i in np.flatnonzero(missed))
        print(
            f"note: {names} did not reach the asked angle within {SETTLE_BUDGET_S:g} s; "
            "gravity holds a soft servo (MuJoCo's) off it, or the arm touches the ground or itself in this pose"
        )
    return 0
