"""`--camera-pose NAME=FILE`: the simulated camera NAME drawn from where a camera file puts it
(so101.bodies.camera_file), for `so101 demos`, `so101 eval` and `so101 teleop`: demonstrations and
scores made from where the user's camera stands. `--looks varied` jitters around it. `--backdrop NAME=IMAGE`:
a photo of the workspace behind camera NAME's scene (so101.bodies.backdrop)."""

from __future__ import annotations

import argparse
from typing import Any, cast

from so101.bodies.backdrop import checked_backdrop
from so101.bodies.camera_file import camera_pose_given
from so101.runtime.argtypes import parsed_by

CAMERA_POSE_HELP = ("draw the simulated camera NAME (front or wrist) from where FILE puts it: a camera file from "
                    "`so101 cameras --fit` or `--default` (repeat for both cameras; default: the simulator's own)")
BACKDROP_HELP = ("draw the photo IMAGE (or one from a folder of them, drawn per episode) behind camera NAME's scene "
                 "(front or wrist), where the floor was: your workspace as that camera sees it, the arm out of view; "
                 "any size, scaled and cropped to the pictures (docs/bodies/backdrop.md)")


class _OnePerCamera(argparse.Action):
    """Gathers an option's NAME=... values into one map by camera; a camera given twice is refused, saying that
    each camera takes one `each`."""

    def __init__(self, *args: Any, each: str, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.each = each

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: object,
                 option_string: str | None = None) -> None:
        name, value = cast(tuple[str, object], values)
        given = dict(getattr(namespace, self.dest) or {})
        if name in given:
            parser.error(f"{option_string} {name}=... is given twice: {self.each} a camera")
        given[name] = value
        setattr(namespace, self.dest, given)


def add_camera_pose_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--camera-pose", dest="camera_poses", type=parsed_by(camera_pose_given), action=_OnePerCamera,
                        each="one file", default={}, metavar="NAME=FILE", help=CAMERA_POSE_HELP)


def add_backdrop_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--backdrop", dest="backdrops", type=parsed_by(checked_backdrop), action=_OnePerCamera,
                        each="one photo, or one folder,", default={}, metavar="NAME=IMAGE", help=BACKDROP_HELP)
