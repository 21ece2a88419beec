"""The camera for headless pictures (`so101 snapshot`, the simulation's `image` output).

Apart from the simulator so that `so101 snapshot --help` can show its defaults without
loading PyBullet.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Camera:
    """A camera orbiting `target_xyz_m`, in PyBullet's yaw/pitch terms (degrees)."""

    target_xyz_m: tuple[float, float, float] = (0.1, -0.05, 0.12)
    distance_m: float = 0.65
    yaw_deg: float = 35.0
    pitch_deg: float = -25.0
    fov_deg: float = 50.0


def check_picture(renders: bool, width: int, height: int) -> None:
    """What every body refuses before drawing: no renderer (made with renders=False), or no pixels."""
    if not renders:
        raise RuntimeError("this simulator was made without its renderer (renders=False): no pictures")
    if width < 1 or height < 1:
        raise ValueError(f"image size must be at least 1x1 pixels, got {width}x{height}")


# Frames the whole arm from the front-right and a little above, whether it reaches
# along +x (home) or is panned ±90° toward ∓y.
DEFAULT_CAMERA = Camera()
