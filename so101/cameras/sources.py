"""Plain rules about real cameras: `--camera NAME=SOURCE` parsed, where a source is, the dataflow's
names for a camera, whether a picture may be scaled to a size, when a picture was captured, and when a
camera has stopped."""

from __future__ import annotations

from pathlib import Path
from typing import Iterable, Mapping

from so101.runtime.dataflow import PICTURE_OF_CAMERA

# The dataset's observation.images.<name> and the policy's inputs: LeRobot's SO-101 guide names its two
# cameras so, and the simulated bodies draw the same two.
CAMERA_NAMES = tuple(PICTURE_OF_CAMERA)
DEFAULT_CAMERA_SIZE = "640x480"  # LeRobot's SO-101 guide's cameras
DEFAULT_CAMERA_FPS = 30
# Two sizes of one shape within this much of each other's aspect ratio: scaling keeps the picture undistorted.
SAME_SHAPE = 0.01
# A real camera that sent no picture for this long has stopped (unplugged, a read that failed, a file that ended):
# the recorder ends its episode, a policy that sees it stops driving. 15 frames at 30 fps: far beyond a late frame.
CAMERA_SILENT_S = 0.5


def parse_camera_option(text: str) -> tuple[str, str]:
    """`front=/dev/video0` -> ("front", "/dev/video0"); ValueError in one line saying what is accepted."""
    name, equals, source = text.partition("=")
    name, source = name.strip(), source.strip()
    if not equals or not source:
        raise ValueError(f"{text!r} is not NAME=SOURCE: e.g. front=/dev/video0, wrist=2 or front=demo.mp4")
    if name not in CAMERA_NAMES:
        raise ValueError(f"{name!r} is not a camera's name here: {' or '.join(CAMERA_NAMES)} "
                         "(the dataset's observation.images.front and .wrist)")
    return name, source


def parse_real_cameras(text: str) -> tuple[str, ...]:
    """`front,wrist` -> ("front", "wrist"); "" -> (); ValueError in one line for another name."""
    names = tuple(name.strip() for name in text.split(",") if name.strip())
    unknown = [name for name in names if name not in PICTURE_OF_CAMERA]
    if unknown:
        raise ValueError(f"{unknown[0]!r} is not a camera: give {' and/or '.join(PICTURE_OF_CAMERA)}, comma-separated")
    return names


def silent_camera(arrived_s: Mapping[str, float], needed: Iterable[str], now_s: float) -> tuple[str, float] | None:
    """(camera, seconds) of the first `needed` camera whose newest picture came (`arrived_s`: camera -> when,
    on the clock of `now_s`) more than CAMERA_SILENT_S ago; None when all send. A camera that has sent
    nothing yet is waited for, not stopped."""
    for name in needed:
        if name in arrived_s and now_s - arrived_s[name] > CAMERA_SILENT_S:
            return name, now_s - arrived_s[name]
    return None


def cameras_given(options: list[tuple[str, str]]) -> dict[str, str]:
    """The `--camera` options as name -> source, in CAMERA_NAMES' order; ValueError for a name given twice."""
    cameras: dict[str, str] = {}
    for name, source in options:
        if name in cameras:
            raise ValueError(f"--camera {name}=... is given twice: one source per camera")
        cameras[name] = source
    return {name: cameras[name] for name in CAMERA_NAMES if name in cameras}


def capture_source(text: str) -> int | str:
    """What OpenCV's VideoCapture opens: a device index (`0`), a `/dev/videoN` path or a video file."""
    raw = text.strip()
    return int(raw) if raw.isdigit() else raw


def is_device(source: int | str) -> bool:
    """A camera (an index or a device node), not a video file: a file plays at its own frame rate."""
    return isinstance(source, int) or str(source).startswith("/dev/")


def source_problem(source: int | str) -> str | None:
    """Why a source cannot be a camera, checked before anything starts: a file that is not there.
    A device that is missing is not a problem now: the camera node tries it again until it comes."""
    if is_device(source) or Path(str(source)).expanduser().is_file():
        return None
    return f"{source} is neither a camera (an index, /dev/videoN) nor a video file"


def scaled_size(given: tuple[int, int], wanted: tuple[int, int]) -> tuple[int, int] | None:
    """The size to scale a `given` picture to for a `wanted` one: None when it is that size already.
    ValueError in one line when the two shapes differ: a picture squeezed into another shape would show
    a policy or a dataset a distorted arm."""
    if given == wanted:
        return None
    (given_width, given_height), (wanted_width, wanted_height) = given, wanted
    if abs(given_width / given_height - wanted_width / wanted_height) > SAME_SHAPE * wanted_width / wanted_height:
        raise ValueError(f"{wanted_width}x{wanted_height} pictures cannot be made from the camera's "
                         f"{given_width}x{given_height} without distorting them: scaled, a picture keeps its shape "
                         f"({given_width}:{given_height})")
    return wanted


def capture_time_s(wall_now_s: float, monotonic_now_s: float, camera_ms: float) -> float:
    """When a picture was captured, on the wall clock the other nodes' messages are stamped with.

    `camera_ms` is OpenCV's CAP_PROP_POS_MSEC for it: with V4L2, the driver's buffer timestamp on the
    monotonic clock (when the camera delivered the frame); taken where it is plausible, under a second
    before now. Otherwise (a backend that gives none, or a position in a file) the moment it was read."""
    age_s = monotonic_now_s - camera_ms / 1000.0
    return wall_now_s - age_s if 0.0 <= age_s < 1.0 else wall_now_s
