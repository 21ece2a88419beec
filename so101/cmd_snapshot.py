"""`so101 snapshot`: the arm in a given pose, rendered headless to a PNG.

No window and no GPU: DIRECT mode and PyBullet's CPU renderer.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from so101.bodies import BODIES, DEFAULT_BODY, SIMULATED_BODIES
from so101.dataflow import TICK_PERIOD_S
from so101.robot import ACTUATED_JOINTS, HOME_POSE_DEG, NUM_ARM_JOINTS

REACHED_TOLERANCE_DEG = 0.5
STILL_DEG_S = 0.5
SETTLE_BUDGET_S = 5.0
MAX_IMAGE_SIDE_PX = 4096


def _image_side(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 16 <= value <= MAX_IMAGE_SIDE_PX:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of pixels from 16 to {MAX_IMAGE_SIDE_PX}")
    return value


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    from so101.camera import DEFAULT_CAMERA

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


def pose_error(pose_deg: list[float] | None) -> str | None:
    """Why a --pose is not acceptable, or None."""
    if pose_deg is None:
        return None
    if len(pose_deg) not in (NUM_ARM_JOINTS, NUM_ARM_JOINTS + 1):
        return f"--pose takes {NUM_ARM_JOINTS} angles (joints 0-4) or {NUM_ARM_JOINTS + 1} (with the gripper), got {len(pose_deg)}"
    for position, (angle, joint) in enumerate(zip(pose_deg, ACTUATED_JOINTS)):
        if not np.isfinite(angle) or not joint.lower_deg <= angle <= joint.upper_deg:
            return (
                f"--pose angle {position} ({joint.name}) is {angle:g}°, "
                f"outside its range [{joint.lower_deg:.1f}°, {joint.upper_deg:.1f}°]"
            )
    return None


def run(args: argparse.Namespace) -> int:
    from PIL import Image

    from so101.camera import DEFAULT_CAMERA, Camera

    error = pose_error(args.pose)
    if not args.distance > 0:
        error = f"--distance must be a positive number of metres, got {args.distance:g}"
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
    simulator = BODIES[args.body].simulator_class()
    with simulator(mode="direct", time_step_s=TICK_PERIOD_S, log=lambda message: None) as sim:
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
        rgb = sim.render_rgb(args.width, args.height, camera)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    # A PNG whatever the name ends in, as before: by default Pillow picks the format from the suffix
    # and fails on one it does not know (`--out arm`).
    Image.fromarray(rgb).save(args.out, format="PNG")
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
