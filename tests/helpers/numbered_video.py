"""Video files that carry each frame's number, to stand in for a camera: frame n shows n in binary as
ten vertical stripes (white 1, black 0; the highest bit leftmost), wide enough to survive any codec,
the dataset's AV1 included, so a recorded video's frames can be read back as the file's numbers."""

from __future__ import annotations

from pathlib import Path

import av
import numpy as np

BITS = 10


def numbered_frame(number: int, width: int, height: int) -> np.ndarray:
    """(height, width, 3) uint8 RGB: `number` as BITS stripes."""
    frame = np.zeros((height, width, 3), dtype=np.uint8)
    stripe = width // BITS
    for bit in range(BITS):
        if number >> (BITS - 1 - bit) & 1:
            frame[:, bit * stripe:(bit + 1) * stripe] = 255
    return frame


def frame_number(rgb: np.ndarray) -> int:
    """The number a numbered_frame (or a decoded, scaled copy of one) shows: each stripe's middle, bright or not."""
    height, width = rgb.shape[:2]
    stripe = width / BITS
    number = 0
    for bit in range(BITS):
        middle = rgb[height // 4:3 * height // 4, int((bit + 0.3) * stripe):int((bit + 0.7) * stripe)]
        number = number << 1 | int(middle.mean() > 127)
    return number


def write_numbered_video(path: Path, frames: int, width: int = 640, height: int = 480, fps: int = 30) -> Path:
    """An MPEG-4 file of `frames` numbered frames at `fps` (a codec every OpenCV build decodes)."""
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
