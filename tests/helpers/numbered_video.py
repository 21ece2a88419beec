"""Video files that carry each frame's number, to stand in for a camera: frame n is three flat grey bands,
left to right, whose brightness are n's three decimal digits (0-999), 25 levels apart. Grey, and big
steps: the dataset's AV1 encoder (SVT-AV1 as the recorder sets it) let through a frame with its
reference's picture where the change was a stripe, or a colour (chroma) step of 25: a recorded
video read back as 0, 1, 2, 2, 4, ... So a recorded video's frames read back as the file's numbers."""

from __future__ import annotations

from pathlib import Path

import av
import numpy as np

LEVEL_STEP = 25  # ten levels per channel, 25 apart: far beyond the codec's and YUV's few units of error
LEVEL_BASE = 10


def numbered_frame(number: int, width: int, height: int) -> np.ndarray:
    """(height, width, 3) uint8 RGB: `number` (0-999) as its digits' levels."""
    digits = (number // 100 % 10, number // 10 % 10, number % 10)
    frame = np.empty((height, width, 3), dtype=np.uint8)
    band = width // 3
    for index, digit in enumerate(digits):
        frame[:, index * band:(index + 1) * band if index < 2 else width] = LEVEL_BASE + LEVEL_STEP * digit
    return frame


def frame_number(rgb: np.ndarray) -> int:
    """The number a numbered_frame (or a decoded, scaled copy of one) shows: its channels' mean levels."""
    height, width = rgb.shape[:2]
    band = width / 3
    means = [rgb[height // 4:3 * height // 4, int((index + 0.25) * band):int((index + 0.75) * band)].mean()
             for index in range(3)]
    digits = [min(9, max(0, round((mean - LEVEL_BASE) / LEVEL_STEP))) for mean in means]
    return digits[0] * 100 + digits[1] * 10 + digits[2]


def write_numbered_video(path: Path, frames: int, width: int = 640, height: int = 480, fps: int = 30) -> Path:
    """An MPEG-4 file of `frames` (up to 1000) numbered frames at `fps` (a codec every OpenCV build decodes)."""
    with av.open(str(path), "w") as container:
        stream = container.add_stream("mpeg4", rate=fps)
        stream.width, stream.height, stream.pix_fmt = width, height, "yuv420p"
        stream.bit_rate = 2_000_000
        for number in range(frames):
            picture = av.VideoFrame.from_ndarray(numbered_frame(number, width, height), format="rgb24")
            for packet in stream.encode(picture):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    return path


def video_frame_numbers(path: Path) -> list[int]:
    """The number each frame of a video file shows, in order (decoded with PyAV)."""
    with av.open(str(path)) as container:
        return [frame_number(frame.to_ndarray(format="rgb24")) for frame in container.decode(video=0)]
