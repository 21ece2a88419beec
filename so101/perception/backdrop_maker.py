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

from typing import Sequence

import numpy as np
import numpy.typing as npt

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
