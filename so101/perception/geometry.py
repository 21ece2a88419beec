"""A camera's geometry as the renderer draws it: points to pixels, and pixels back to rays and to
the table. Pure numpy, so the perception node, its training and the tests share one model.

A `Camera` (so101.bodies.camera) orbits its target in PyBullet's yaw/pitch terms; MuJoCo's free
camera draws it at azimuth yaw + 90° and elevation pitch, turned by `roll_deg`, with `fov_deg` the vertical
field of view.
Pixels: u to the right, v down, (0, 0) the top-left pixel's corner, so a pixel's centre is at +0.5.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from so101.bodies.camera import Camera

Points = npt.NDArray[np.float64]


@dataclass(frozen=True)
class View:
    """A camera drawn at `width` x `height`: its eye, its unit axes (forward, right, up) and focal length in pixels."""

    eye: Points
    forward: Points
    right: Points
    up: Points
    focal_px: float
    width: int
    height: int

    def project(self, points_m: npt.ArrayLike) -> Points:
        """(N, 3) points in the base frame to (N, 2) pixels (u, v); points behind the camera give nan."""
        relative = np.atleast_2d(np.asarray(points_m, dtype=float)) - self.eye
        depth = relative @ self.forward
        with np.errstate(divide="ignore", invalid="ignore"):
            u = self.width / 2 + self.focal_px * (relative @ self.right) / depth
            v = self.height / 2 - self.focal_px * (relative @ self.up) / depth
        pixels = np.stack([u, v], axis=1)
        pixels[depth <= 0] = np.nan
        return pixels

    def rays(self, pixels: npt.ArrayLike) -> Points:
        """(N, 2) pixels to (N, 3) unit directions from the eye."""
        pixels = np.atleast_2d(np.asarray(pixels, dtype=float))
        directions = (self.forward[None, :] * self.focal_px
                      + (pixels[:, :1] - self.width / 2) * self.right[None, :]
                      - (pixels[:, 1:2] - self.height / 2) * self.up[None, :])
        norms: Points = np.linalg.norm(directions, axis=1, keepdims=True)
        return directions / norms

    def on_plane(self, pixels: npt.ArrayLike, height_m: npt.ArrayLike) -> Points:
        """(N, 3) points where the pixels' rays meet the horizontal planes z = height_m (one, or one each);
        nan where a ray runs away from its plane."""
        directions = self.rays(pixels)
        heights = np.broadcast_to(np.asarray(height_m, dtype=float), (len(directions),))
        with np.errstate(divide="ignore", invalid="ignore"):
            along = (heights - self.eye[2]) / directions[:, 2]
        along = np.where(along > 0, along, np.nan)
        points: Points = self.eye[None, :] + along[:, None] * directions
        return points


def view_of(camera: Camera, width: int, height: int) -> View:
    """`camera` drawn at `width` x `height` pixels, as MuJoCo's free camera draws it (turned by its roll)."""
    eye, forward, right, up = (np.asarray(axis, dtype=float) for axis in camera.axes())
    focal_px = (height / 2) / math.tan(math.radians(camera.fov_deg) / 2)
    return View(eye, forward, right, up, focal_px, width, height)
