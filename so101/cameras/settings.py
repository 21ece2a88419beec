"""The real camera node's settings (nodes/real_camera.py): opencv-video-capture's environment
contract (dora-hub's node: CAPTURE_PATH, IMAGE_WIDTH, IMAGE_HEIGHT, ENCODING), and this project's
name, capture size and rate. `so101 teleop --camera` sets them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

from so101.cameras.sources import CAMERA_NAMES, DEFAULT_CAMERA_FPS, capture_source
from so101.runtime.settings import (
    EnvironSettings, Setting, read_choice, read_fps, read_image_size, setting,
)

ENCODINGS = ("rgb8", "bgr8")  # the recorder and the policy read rgb8


def read_source(environ: Mapping[str, str], declared_setting: Setting) -> int | str:
    return capture_source(declared_setting.raw(environ))


def read_optional_pixels(environ: Mapping[str, str], declared_setting: Setting) -> int | None:
    """A width or height in pixels, or None for an empty value (the camera's own)."""
    raw = declared_setting.raw(environ).strip()
    if not raw:
        return None
    if not raw.isdigit() or not 16 <= int(raw) <= 4096 or int(raw) % 2:
        raise ValueError(f"{declared_setting.env_var}={raw!r} is not an even number of pixels from 16 to 4096, "
                         "or empty for the camera's own")
    return int(raw)


@dataclass(frozen=True)
class RealCameraSettings(EnvironSettings):
    """nodes/real_camera.py."""

    source: int | str = setting(
        "CAPTURE_PATH", "", "the camera: a device index (`0`), a `/dev/videoN` path, or a video file (played at its "
        "own frame rate)", read_source, required="(so101 teleop --camera NAME=SOURCE, or the dataflow's env:)")
    width: int | None = setting("IMAGE_WIDTH", "", "the pictures' width; empty = the camera's own", read_optional_pixels)
    height: int | None = setting("IMAGE_HEIGHT", "", "the pictures' height; empty = the camera's own",
                                 read_optional_pixels)
    encoding: str = setting("ENCODING", "rgb8", "`rgb8` (what the recorder and a policy read) or `bgr8`",
                            read_choice(ENCODINGS))
    name: str = setting("SO101_CAMERA_NAME", "front", "which camera it is, in its log lines: `front` or `wrist`",
                        read_choice(CAMERA_NAMES))
    capture_size: tuple[int, int] | None = setting(
        "SO101_CAMERA_SIZE", "", "WIDTHxHEIGHT asked of a device (the pictures are scaled from it to IMAGE_WIDTH x "
        "IMAGE_HEIGHT, the same shape); empty = that size", read_image_size)
    fps: int = setting("SO101_CAMERA_FPS", str(DEFAULT_CAMERA_FPS), "frames per second asked of a device "
                       "(a file plays at its own)", read_fps(240))

    def __post_init__(self) -> None:
        if (self.width is None) != (self.height is None):
            raise ValueError("IMAGE_WIDTH and IMAGE_HEIGHT go together: set both, or neither for the camera's own size")

    @property
    def size(self) -> tuple[int, int] | None:
        """The pictures' (width, height), or None for the camera's own."""
        if self.width is None or self.height is None:
            return None
        return self.width, self.height
