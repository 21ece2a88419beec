"""Reading the project's pictures in tests: PNG size and pixels, and where the arm is in a CPU render."""

from __future__ import annotations

import io

import numpy as np
from PIL import Image


def open_png(data: bytes) -> Image.Image:
    """The picture in data, which must be a PNG: Pillow would open other formats just as well."""
    image = Image.open(io.BytesIO(data))
    assert image.format == "PNG"
    return image


def png_size(data: bytes) -> tuple[int, int]:
    """(width, height) of a PNG."""
    return open_png(data).size


def png_rgb(data: bytes) -> np.ndarray:
    """A PNG's pixels as (H, W, 3) uint8."""
    return np.asarray(open_png(data).convert("RGB"))


def arm_pixels(rgb: np.ndarray) -> np.ndarray:
    """The SO-101's yellow in PyBullet's CPU render: the floor is white and pale blue, so only
    the arm is red+green with little blue. (The GUI's shaded screenshot needs other thresholds:
    tests/helpers/screen.py has its own.)"""
    red, green, blue = (rgb[:, :, channel].astype(int) for channel in range(3))
    return (red > 150) & (green > 110) & (blue < 90)
