"""`so101 assets`: fetch and verify the model files."""

from __future__ import annotations

import argparse
from pathlib import Path

from so101 import assets


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    parser.add_argument(
        "--dir", type=Path, default=None,
        help=f"where to put the model (default: ${assets.ASSETS_ENV_VAR}, else assets/SO101 in this checkout)",
    )
    parser.add_argument("--check", action="store_true", help="only verify; never download (exit 2 if not valid)")


def run(args: argparse.Namespace) -> int:
    if args.check:
        urdf = assets.urdf_path(args.dir)
        print(f"SO-101 model verified: {urdf.parent} ({len(assets.manifest())} files)")
        return 0
    urdf = assets.fetch(args.dir)
    from so101.bodies.mujoco_model import collision_hulls  # imports MuJoCo: only here, not for --check

    collision_hulls(urdf.with_name(assets.MJCF_NAME))  # MuJoCo's collision meshes, derived once
    from so101.bodies.pybullet_hulls import collision_hulls_urdf

    collision_hulls_urdf(urdf)  # PyBullet's: each collision mesh's hull points, derived once
    from so101.bodies.camera_meshes import camera_meshes

    camera_meshes(urdf.parent)  # a task's cameras' meshes, with fewer triangles, derived once
    return 0
