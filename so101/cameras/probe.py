"""A camera or a video file tried before it is used: a source that is not there, or a file with no video,
said in one line before OpenCV tries it (and warns on the terminal); then the size of its first picture."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from so101.cameras.capture import VideoSource
from so101.cameras.sources import DEFAULT_CAMERA_FPS, is_device

FIRST_PICTURE_S = 10.0  # a camera that gives no picture in this long gives none
CAMERA_ASKED_SIZE = (640, 480)  # what a device is asked for: LeRobot's SO-101 guide's cameras


class ProbeError(Exception):
    """A source that gives no picture; str() is one line for the person."""


def video_file_problem(path: str) -> str | None:
    """Why a file cannot stand in for a camera, asked of FFmpeg through PyAV, which keeps quiet (OpenCV's own
    FFmpeg writes its complaint on the terminal before our line); None for a file with a video."""
    import av

    try:
        with av.open(str(Path(path).expanduser())) as container:
            return None if container.streams.video else "it has no video stream"
    except av.FFmpegError as error:
        return f"not a video ({error.strerror})"


def device_problem(source: int | str) -> str | None:
    """A Linux camera that is not there, said before OpenCV tries it (and warns on the terminal); None otherwise."""
    path = f"/dev/video{source}" if isinstance(source, int) else str(source)
    if sys.platform.startswith("linux") and path.startswith("/dev/") and not Path(path).exists():
        return f"no {path} here (`so101 cameras` lists the cameras this computer has)"
    return None


def first_picture(source: int | str, where: str, name: str) -> tuple[int, int]:
    """The size of the first picture `source` gives (within FIRST_PICTURE_S); ProbeError otherwise."""
    problem = device_problem(source) if is_device(source) else video_file_problem(str(source))
    if problem is not None:
        raise ProbeError(f"camera {name}: {where}: {problem}")
    probe = VideoSource(source, None, CAMERA_ASKED_SIZE if is_device(source) else None, DEFAULT_CAMERA_FPS)
    why = probe.open()
    if why is not None:
        raise ProbeError(f"camera {name}: {where}: {why}")
    try:
        deadline = time.monotonic() + FIRST_PICTURE_S
        while time.monotonic() < deadline:
            read = probe.read()
            if read is not None:
                return read[0].shape[1], read[0].shape[0]
            if not is_device(source):
                break  # a file that gives no first picture gives none later
            time.sleep(0.05)
    finally:
        probe.close()
    raise ProbeError(f"camera {name}: {where} gave no picture (a camera in use by another program, or a video "
                     "file with none?)")
