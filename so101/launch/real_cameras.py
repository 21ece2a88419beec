"""The real arm's cameras in `so101 teleop`: `--camera NAME=SOURCE` checked before anything starts, and
one real camera node per camera added to the dataflow (so101.runtime.dataflow.with_real_cameras),
its pictures at the size the recording or a policy that sees takes, scaled from the size asked of
the camera where the two have one shape."""

from __future__ import annotations

from pathlib import PurePath

from so101.cameras.sources import cameras_given, capture_source, scaled_size, source_problem
from so101.runtime.dataflow import PICTURE_OF_CAMERA, ROOT, picture_sources, with_real_cameras


def checked_cameras(options: list[tuple[str, str]] | None, simulated: bool) -> dict[str, str]:
    """The `--camera` options as name -> source; ValueError in one line for a simulated body, a name
    given twice or a source that is neither a camera nor a video file."""
    cameras = cameras_given(options or [])
    if cameras and simulated:
        raise ValueError("--camera is for --body real: a simulated body draws its own front and wrist cameras")
    for source in cameras.values():
        problem = source_problem(capture_source(source))
        if problem:
            raise ValueError(f"--camera: {problem}")
    return cameras


def policy_picture_problem(needed: tuple[str, ...], cameras: dict[str, str], camera_size: tuple[int, int],
                           policy_size: tuple[int, int], recording: bool) -> str | None:
    """Why the cameras cannot give a policy that sees its pictures, in one line; None when they can
    (scaled from `camera_size` where the policy's size is another of the same shape)."""
    missing = [name for name, picture in PICTURE_OF_CAMERA.items() if picture in needed and name not in cameras]
    if missing:
        wanted = " ".join(f"--camera {name}=SOURCE" for name, picture in PICTURE_OF_CAMERA.items() if picture in needed)
        return f"the policy sees the {' and '.join(missing)} camera, which is not given: add {wanted}"
    width, height = policy_size
    if recording and camera_size != policy_size:
        return (f"the policy sees {width}x{height} pictures, and the cameras' pictures are recorded too: "
                f"record at --camera-size {width}x{height}, or run the policy without --record")
    try:
        scaled_size(camera_size, policy_size)
    except ValueError as error:
        return f"the policy sees {width}x{height} pictures: {error}; give --camera-size of the policy's shape"
    return None


def add_real_cameras(descriptor: dict, cameras: dict[str, str], camera_size: tuple[int, int],
                     picture_size: tuple[int, int], fps: int, root: PurePath = ROOT) -> None:
    """One real camera node per camera (none when the dataflow has them already): each asks its camera for
    `camera_size` at `fps` and sends `picture_size` pictures."""
    if picture_sources(descriptor) or not cameras:
        return
    capture = f"{camera_size[0]}x{camera_size[1]}"
    with_real_cameras(descriptor, {name: {
        "CAPTURE_PATH": source, "IMAGE_WIDTH": str(picture_size[0]), "IMAGE_HEIGHT": str(picture_size[1]),
        "ENCODING": "rgb8", "SO101_CAMERA_NAME": name, "SO101_CAMERA_SIZE": capture, "SO101_CAMERA_FPS": str(fps),
    } for name, source in cameras.items()}, root)

