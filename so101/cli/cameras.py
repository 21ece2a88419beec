"""`so101 cameras`: the cameras this computer has (V4L2 capture devices: path, name, the sizes and
frame rates each offers), as `lerobot-find-cameras opencv` lists them; `--save DIR` keeps one picture
from each, to see which camera is which before `so101 teleop --body real --camera front=...`."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from so101.cameras.listing import find_cameras, listing_lines, picture_file_name

# A camera's first pictures are often dark or half-exposed while it adjusts: this many are let go first.
WARM_UP_PICTURES = 10


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    parser.add_argument("--save", type=Path, metavar="DIR", default=None,
                        help="also save one picture from each camera in DIR (made if missing), as videoN.png")


def save_picture(path: str, folder: Path) -> str:
    """One picture of the camera at `path` in `folder`; the line that says where, or why not."""
    import cv2

    from so101.cameras.capture import VideoSource

    source = VideoSource(path, None, None, 30)
    why = source.open()
    if why is not None:
        return f"{path}: no picture saved: {why} (in use by another program?)"
    try:
        read = None
        for _ in range(WARM_UP_PICTURES):
            read = source.read() or read
    finally:
        source.close()
    if read is None:
        return f"{path}: no picture saved: it gave none (in use by another program?)"
    rgb = read[0]
    target = folder / picture_file_name(path)
    if not cv2.imwrite(str(target), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
        return f"{path}: no picture saved: {target} cannot be written"
    return f"{path}: saved {target} ({rgb.shape[1]}x{rgb.shape[0]})"


def run(args: argparse.Namespace) -> int:
    cameras = find_cameras()
    for line in listing_lines(cameras):
        print(line)
    if args.save is not None and cameras:
        folder = args.save.expanduser()
        folder.mkdir(parents=True, exist_ok=True)
        for camera in cameras:
            print(save_picture(camera.path, folder))
    sys.stdout.flush()
    return 0
