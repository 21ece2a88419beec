"""Reading the project's pictures in tests: PNG size and pixels, and where the arm is in a CPU render."""

from __future__ import annotations

import io
import struct

import numpy as np


def png_size(data: bytes) -> tuple[int, int]:
    """(width, height) from a PNG's header."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def png_rgb(data: bytes) -> np.ndarray:
    """A PNG's pixels as (H, W, 3) uint8, decoded by matplotlib (not by our own encoder)."""
    from matplotlib import image

    return (image.imread(io.BytesIO(data))[:, :, :3] * 255).round().astype(np.uint8)


def arm_pixels(rgb: np.ndarray) -> np.ndarray:
    """The SO-101's yellow in PyBullet's CPU render: the floor is white and pale blue, so only
    the arm is red+green with little blue. (The GUI's shaded screenshot needs other thresholds:
    tests/test_gui.py has its own.)"""
    red, green, blue = (rgb[:, :, channel].astype(int) for channel in range(3))
    return (red > 150) & (green > 110) & (blue < 90)
