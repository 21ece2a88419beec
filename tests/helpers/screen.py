"""An Xvfb display's screen in tests: the marks a test of a window carries, screenshots
(ImageMagick `import`), and the arm in them: the only yellow thing in PyBullet's and MuJoCo's scenes."""

from __future__ import annotations

import shutil
import subprocess
import time

import numpy as np
import pytest
from PIL import Image

GUI_MARKS = [
    pytest.mark.person,
    pytest.mark.skipif(shutil.which("Xvfb") is None, reason="Xvfb is not installed (Debian package xvfb)"),
    pytest.mark.skipif(shutil.which("import") is None, reason="ImageMagick's `import` is not installed (package imagemagick)"),
]

MIN_ARM_PIXELS = 2000  # the arm covers about 15,000 pixels of the 1024x768 window
SAME_FRAME_OVERLAP = 0.98  # two screenshots of an arm at rest


def screenshot(display: str, path) -> np.ndarray:
    subprocess.run(["import", "-display", display, "-window", "root", str(path)], check=True, timeout=60)
    return np.asarray(Image.open(path).convert("RGB")).astype(int)


def arm_pixels(rgb: np.ndarray) -> np.ndarray:
    """Yellow pixels: red and green high, blue low (shaded yellow included, floor and sky excluded)."""
    red, green, blue = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return (red > 120) & (green > 80) & (blue < 0.45 * green) & (green < 0.95 * red)


def overlap(mask_a: np.ndarray, mask_b: np.ndarray) -> float:
    return (mask_a & mask_b).sum() / max(1, (mask_a | mask_b).sum())


def settled_arm(display, path, accept, timeout_s=60):
    """Screenshots until the arm looks the same in two in a row and `accept(mask)` holds; returns that mask.

    Two equal frames rule out a scene still loading (links drawn before they are
    placed) and an arm still on its way.
    """
    deadline = time.monotonic() + timeout_s
    previous = arm_pixels(screenshot(display, path))
    while True:
        time.sleep(0.5)
        mask = arm_pixels(screenshot(display, path))
        if (overlap(previous, mask) > SAME_FRAME_OVERLAP and accept(mask)) or time.monotonic() > deadline:
            return mask
        previous = mask
