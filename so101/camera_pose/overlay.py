"""The overlay `so101 cameras --align` shows, as plain functions of pictures: the simulated arm's mask
over the live picture (tinted, outlined), how much of its outline lies on the picture's edges, and the
lines the window and the browser's panel write beside it."""

from __future__ import annotations

from typing import Sequence

import numpy as np
import numpy.typing as npt

RgbImage = npt.NDArray[np.uint8]
Mask = npt.NDArray[np.bool_]

# How the simulated arm is drawn over the live picture: a blue tint where it is (the real arm is yellow: where
# the two overlap it turns grey, where the real one sticks out it stays yellow), its outline in magenta on top,
# 2 pixels wide at 640 (seen at a glance on a picture the window scales).
TINT_RGB = (0, 90, 255)
TINT_OPACITY = 0.45
OUTLINE_RGB = (255, 0, 255)
OUTLINE_PX_AT_640 = 2
# An outline pixel this close to one of the live picture's edges lies on it, whatever the picture's size: wider,
# a shifted arm's outline meets the real arm's own inner edges (its holes, its servos) and seems to agree.
NEAR_EDGE_PX = 2.0
# The window's picture is scaled to this width at least, and at most (a 320x240 camera doubled).
WINDOW_WIDTH_PX = (640, 1280)

def outline_of(mask: Mask, thickness_px: int = 1) -> Mask:
    """The pixels of `mask` within `thickness_px` of its edge (inside it): the arm's outline."""
    import cv2

    if not mask.any():
        return np.zeros_like(mask)
    kernel = np.ones((2 * thickness_px + 1, 2 * thickness_px + 1), np.uint8)
    inner = cv2.erode(mask.astype(np.uint8), kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    return mask & (inner == 0)


def overlay_picture(live: RgbImage, arm: Mask) -> RgbImage:
    """The live picture with the simulated arm (`arm`: its pixels, at the picture's size) over it: tinted
    where it is, its outline drawn, so the real arm sticking out of it, or the tint on the floor, shows
    the mismatch."""
    if live.shape[:2] != arm.shape:
        raise ValueError(f"the mask is {arm.shape[1]}x{arm.shape[0]}, the picture {live.shape[1]}x{live.shape[0]}")
    picture = live.astype(np.float32)
    picture[arm] = (1.0 - TINT_OPACITY) * picture[arm] + TINT_OPACITY * np.asarray(TINT_RGB, np.float32)
    picture[outline_of(arm, max(1, round(OUTLINE_PX_AT_640 * live.shape[1] / 640)))] = OUTLINE_RGB
    return np.clip(picture + 0.5, 0, 255).astype(np.uint8)


def picture_edges(live: RgbImage) -> Mask:
    """The live picture's edges (Canny's, on its grey, a little smoothed against sensor noise)."""
    import cv2

    grey = cv2.GaussianBlur(cv2.cvtColor(live, cv2.COLOR_RGB2GRAY), (5, 5), 0)
    edges: Mask = cv2.Canny(grey, 40, 120) > 0
    return edges


def outline_on_edges(live: RgbImage, arm: Mask) -> float | None:
    """The share (0 to 1) of the simulated arm's outline that lies on an edge of the live picture: near 1
    when the two arms coincide; None when the arm is not in the picture at all."""
    import cv2

    outline = outline_of(arm)
    if not outline.any():
        return None
    edges = picture_edges(live)
    if not edges.any():
        return 0.0
    # The distance from every pixel to the nearest edge (the edges are the zeros).
    distance = cv2.distanceTransform(np.where(edges, 0, 255).astype(np.uint8), cv2.DIST_L2, 3)
    return float(np.mean(distance[outline] <= NEAR_EDGE_PX))


def agreement_text(share: float | None) -> str:
    if share is None:
        return "the simulated arm is not in the picture"
    return f"{round(100 * share)}% of the simulated arm's outline lies on the picture's edges"


def window_size(width: int, height: int) -> tuple[int, int]:
    """The window for a `width` x `height` picture: scaled, its shape kept, to WINDOW_WIDTH_PX."""
    smallest, largest = WINDOW_WIDTH_PX
    scale = smallest / width if width < smallest else largest / width if width > largest else 1.0
    return round(width * scale), round(height * scale)


def window_lines(words: str | None, agreement: str) -> list[str]:
    """What the window writes over its foot: the fitted file's words, a clause a line, and the agreement."""
    lines = ["from the fitted file:"] + [f"  {clause}" for clause in words.split("; ")] if words is not None else []
    return lines + [agreement]


def panel_markdown(name: str, simulated_from: str, agreement: str, words: str | None,
                   angles_deg: Sequence[float] | None) -> str:
    """What the browser's panel says beside the overlay."""
    lines = [f"**so101 cameras --align {name}**",
             f"The live picture; over it, tinted blue in a magenta outline, the simulated {name} camera's arm "
             f"({simulated_from}) at the real arm's angles. Move the camera until the real arm fills the outline.",
             f"**{agreement}**"]
    if words is not None:
        lines.append(f"From the fitted file: {words}")
    if angles_deg is not None:
        lines.append("Arm: " + ", ".join(f"{round(angle, 1) + 0.0:.1f}°" for angle in angles_deg))
    return "\n\n".join(lines)
