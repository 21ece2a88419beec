"""`--camera-pose NAME=FILE`: the simulated camera NAME drawn from where a camera file puts it
(so101.bodies.camera_file), for `so101 demos`, `so101 eval` and `so101 teleop`: demonstrations and
scores made from where the user's camera stands. `--looks varied` jitters around it."""

from __future__ import annotations

import argparse
from typing import cast

from so101.bodies.backdrop import BackdropError, checked_backdrop
from so101.bodies.camera_file import CameraFile, CameraFileError, camera_pose_given

CAMERA_POSE_HELP = ("draw the simulated camera NAME (front or wrist) from where FILE puts it: a camera file from "
                    "`so101 cameras --fit` or `--default` (repeat for both cameras; default: the simulator's own)")


def camera_pose(text: str) -> tuple[str, CameraFile]:
    """argparse's type for NAME=FILE: the camera's name and its file, read and checked now."""
    try:
        return camera_pose_given(text)
    except CameraFileError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


class _CameraPoses(argparse.Action):
    """Gathers the --camera-pose options into one map (args.camera_poses); a camera given twice is refused."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: object,
                 option_string: str | None = None) -> None:
        name, pose = cast(tuple[str, CameraFile], values)
        poses = dict(getattr(namespace, self.dest) or {})
        if name in poses:
            parser.error(f"--camera-pose {name}=... is given twice: one file a camera")
        poses[name] = pose
        setattr(namespace, self.dest, poses)


def add_camera_pose_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--camera-pose", dest="camera_poses", type=camera_pose, action=_CameraPoses, default={},
                        metavar="NAME=FILE", help=CAMERA_POSE_HELP)


BACKDROP_HELP = ("draw the photo IMAGE (or one from a folder of them, drawn per episode) behind camera NAME's scene "
                 "(front or wrist), where the floor was: your workspace as that camera sees it, the arm out of view; "
                 "any size, scaled and cropped to the pictures (docs/bodies/backdrop.md)")


def backdrop(text: str) -> tuple[str, str]:
    """argparse's type for NAME=IMAGE: the camera's name and the photos' path, each read once now."""
    try:
        return checked_backdrop(text)
    except BackdropError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


class _Backdrops(argparse.Action):
    """Gathers the --backdrop options into one map (args.backdrops); a camera given twice is refused."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: object,
                 option_string: str | None = None) -> None:
        name, path = cast(tuple[str, str], values)
        given = dict(getattr(namespace, self.dest) or {})
        if name in given:
            parser.error(f"--backdrop {name}=... is given twice: one photo, or one folder, a camera")
        given[name] = path
        setattr(namespace, self.dest, given)


def add_backdrop_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--backdrop", dest="backdrops", type=backdrop, action=_Backdrops, default={},
                        metavar="NAME=IMAGE", help=BACKDROP_HELP)
