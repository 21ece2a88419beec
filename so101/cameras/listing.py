"""`so101 cameras`'s list: the V4L2 capture devices (from /sys/class/video4linux, asked through
v4l2.py), each with its name and the sizes and frame rates it offers, as lines to print."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from so101.cameras.v4l2 import Mode, query

SYSFS = Path("/sys/class/video4linux")


@dataclass(frozen=True)
class CameraFound:
    path: str  # /dev/videoN
    name: str  # the driver's, e.g. "USB 2.0 Camera: USB Camera"
    modes: tuple[Mode, ...]


def _number(entry: Path) -> int:
    match = re.search(r"(\d+)$", entry.name)
    return int(match.group(1)) if match else -1


def find_cameras(sysfs: Path = SYSFS, ask: Callable[[str], list[Mode] | None] = query,
                 dev: Path = Path("/dev")) -> list[CameraFound]:
    """The capture devices, in their number's order; nodes that capture nothing (a USB camera's
    metadata node) are left out."""
    if not sysfs.is_dir():
        return []
    found = []
    for entry in sorted(sysfs.glob("video*"), key=_number):
        path = str(dev / entry.name)
        modes = ask(path)
        if modes is None:
            continue
        name_file = entry / "name"
        name = name_file.read_text(encoding="utf-8", errors="replace").strip() if name_file.is_file() else "?"
        found.append(CameraFound(path, name, tuple(modes)))
    return found


def listing_lines(cameras: list[CameraFound]) -> list[str]:
    """What `so101 cameras` prints: each camera, then one line per pixel format and size with its rates."""
    if not cameras:
        return ["no cameras: no V4L2 capture device under /dev/video* (plugged in? `ls /dev/video*`; "
                "a video file works as a camera: --camera front=FILE)"]
    lines = []
    for camera in cameras:
        lines.append(f"{camera.path}  {camera.name}")
        for mode in sorted(camera.modes, key=lambda each: (each.pixel_format, -each.width * each.height)):
            rates = ", ".join(f"{rate:g}" for rate in mode.fps) or "?"
            lines.append(f"    {mode.pixel_format:<4} {mode.width}x{mode.height}  {rates} fps")
        if not camera.modes:
            lines.append("    (it lists no sizes)")
    return lines


def picture_file_name(path: str) -> str:
    """Where `so101 cameras --save DIR` puts a camera's picture: video0.png for /dev/video0."""
    return f"{Path(path).name}.png"
