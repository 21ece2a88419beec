"""A backdrop made from what a camera saw (`so101 cameras --backdrop NAME --from SOURCE -o FILE.png`).

Each pixel of the backdrop is the median of that pixel over many frames, counting only the frames in which
the arm does not cover it. From a live camera or a video, the arm is moved out of view, or keeps moving, and
every frame counts whole. From a recorded episode, the simulator draws the arm (and the cube of a simulated
task) at each frame's joints, from where the camera stands (a camera file: `so101 cameras --fit`), and those
pixels, grown by a margin for the fit's error, are left out. A pixel the arm covered in every frame is a hole:
the holes are filled from around them (OpenCV's inpainting), and a backdrop with more than a stated share of
them is refused.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from so101.bodies.camera_file import CameraFile

MAX_FRAMES = 120  # frames a backdrop is the median of: evenly spread over what the source gives
DEFAULT_MAX_HOLES = 0.05  # the most of the picture that may be filled from around rather than seen


class BackdropMakingError(ValueError):
    """A backdrop that cannot be made; str() is one line."""


def spread(count: int, most: int = MAX_FRAMES) -> list[int]:
    """At most `most` frame indices evenly spread over `count` frames."""
    return sorted({round(index) for index in np.linspace(0, count - 1, min(count, most))}) if count else []


def median_backdrop(frames: Sequence[npt.NDArray[np.uint8]], covered: Sequence[npt.NDArray[np.bool_]] | None = None,
                    max_holes: float = DEFAULT_MAX_HOLES) -> tuple[npt.NDArray[np.uint8], float]:
    """The backdrop of `frames` (each HxWx3 uint8), leaving out the pixels `covered` marks in each (None: none),
    and the share of its pixels seen in some frame; BackdropMakingError in one line past `max_holes`."""
    import cv2

    if not frames:
        raise BackdropMakingError("no frames to make a backdrop from")
    stack = np.stack(frames).astype(np.float32)
    if covered is None:
        return np.median(stack, axis=0).astype(np.uint8), 1.0
    stack[np.stack(covered)] = np.nan
    seen = ~np.all(np.isnan(stack[..., 0]), axis=0)
    share = float(seen.mean())
    if 1 - share > max_holes:
        raise BackdropMakingError(f"the arm covers {1 - share:.1%} of the picture in every frame, more than "
                                  f"{max_holes:.0%}: record the arm moving over more of the workspace, or away from it")
    picture: npt.NDArray[np.uint8] = np.zeros(stack.shape[1:], dtype=np.uint8)
    if seen.any():
        picture[seen] = np.nanmedian(stack[:, seen], axis=0).round().astype(np.uint8)
    if not seen.all():
        picture = np.asarray(cv2.inpaint(picture, (~seen).astype(np.uint8) * 255, 5, cv2.INPAINT_TELEA), dtype=np.uint8)
    return picture, share


def grown(mask: npt.NDArray[np.bool_], margin_px: int) -> npt.NDArray[np.bool_]:
    """`mask` grown by `margin_px` pixels each way (a fitted camera is a few pixels off)."""
    import cv2

    if margin_px <= 0:
        return mask
    kernel = np.ones((2 * margin_px + 1, 2 * margin_px + 1), dtype=np.uint8)
    return cv2.dilate(mask.astype(np.uint8), kernel).astype(bool)


def source_frames(text: str, most: int = 600) -> list:
    """Up to `most` frames of a camera or a video file, as fast as it gives them, spread to the backdrop's."""
    from so101.cameras.capture import VideoSource
    from so101.cameras.sources import capture_source, is_device

    given = capture_source(text)
    source = VideoSource(given, None, None, 30, sleep=lambda seconds: None)
    why = source.open()
    if why is not None:
        raise BackdropMakingError(f"{text}: {why}")
    frames = []
    try:
        for _ in range(90 if is_device(given) else most):  # a camera: three seconds
            read = source.read()
            if read is None:
                break
            frames.append(read[0])
    finally:
        source.close()
    if not frames:
        raise BackdropMakingError(f"{text} gave no picture")
    return [frames[index] for index in spread(len(frames))]


def episode_frames(root: Path, episode: int, pose: CameraFile | None, units: str | None = None,
                   calibration: Path | None = None) -> tuple[list, list, str]:
    """Episode `episode`'s front pictures and, in each, where the simulator draws the arm (and a simulated task's
    cube) from the camera file `pose` (None: the one its scenario keeps), grown by a margin; its joints' units
    as so101.dataset.units reads them (`units`, the recording follower's `calibration`)."""
    from so101.bodies.camera_file import CameraFileError, camera_file_from, orbit_of
    from so101.bodies.task_cameras import TaskCameras
    from so101.dataset.features import ENVIRONMENT_KEY, IMAGE_KEY, STATE_KEY
    from so101.dataset.layout import DatasetError, episode_scenario
    from so101.dataset.reader import Dataset
    from so101.tasks import CUBE_TO_BOX

    try:
        dataset = Dataset.open(root)
        kept = episode_scenario(dataset.info, episode).get("cameras", {}).get("front")  # a simulated episode's
        pose = pose or (camera_file_from(kept, "front") if kept else None)
        if pose is None:
            raise BackdropMakingError(f"--backdrop front --from {root} needs --camera-pose front=FILE: where the "
                                      f"camera stood (so101 cameras --fit front --from {root} -o FILE)")
        states = dataset.episode_joints_deg(episode, dataset.joint_units(units, calibration, episode))[STATE_KEY]
        objects = dataset.episode_frames(episode).get(ENVIRONMENT_KEY)
        chosen = set(spread(len(states)))
        pictures = {index: picture for index, picture in enumerate(dataset.episode_images(episode, IMAGE_KEY))
                    if index in chosen}
    except (DatasetError, CameraFileError) as error:
        raise BackdropMakingError(str(error)) from None
    frames, covered = [], []
    with TaskCameras(CUBE_TO_BOX if objects is not None else None, log=lambda line: None) as cameras:
        camera = orbit_of(pose)
        for index, picture in sorted(pictures.items()):
            height, width = picture.shape[:2]
            mask = cameras.arm_mask(states[index], camera, width, height, objects[index] if objects is not None else ())
            frames.append(picture)
            covered.append(grown(mask, max(2, width // 40)))
    return frames, covered, "the episode's pictures with the arm left out"
