"""What a V4L2 device says it offers, asked with the kernel's own ioctls (linux/videodev2.h): its
name and, per pixel format, its frame sizes and their frame rates. Linux only; stdlib only.
linuxpy 0.25 (PyPI's V4L2 bindings) was not used: it is GPL-3.0-or-later, which this Apache-2.0 project
would take on by importing it, and its listing skips stepwise sizes and drops pixel formats its enum lacks."""

from __future__ import annotations

import fcntl
import os
import struct
from dataclasses import dataclass

# _IOR/_IOWR('V', nr, struct): direction << 30 | size << 16 | 'V' << 8 | nr, with the structs' sizes.
VIDIOC_QUERYCAP = 0x80685600  # struct v4l2_capability, 104 bytes
VIDIOC_ENUM_FMT = 0xC0405602  # struct v4l2_fmtdesc, 64 bytes
VIDIOC_ENUM_FRAMESIZES = 0xC02C564A  # struct v4l2_frmsizeenum, 44 bytes
VIDIOC_ENUM_FRAMEINTERVALS = 0xC034564B  # struct v4l2_frmivalenum, 52 bytes
CAPTURE = 1  # V4L2_BUF_TYPE_VIDEO_CAPTURE, and V4L2_CAP_VIDEO_CAPTURE
DEVICE_CAPS = 0x80000000  # V4L2_CAP_DEVICE_CAPS: device_caps holds this node's own capabilities
DISCRETE = 1  # V4L2_FRMSIZE_TYPE_DISCRETE, V4L2_FRMIVAL_TYPE_DISCRETE


@dataclass(frozen=True)
class Mode:
    """One size of one pixel format, and the frame rates it offers (frames per second)."""

    pixel_format: str  # the fourcc: MJPG, YUYV, ...
    width: int
    height: int
    fps: tuple[float, ...]


def _ask(fd: int, request: int, packed: bytes) -> bytes | None:
    """The ioctl's answer, or None where the driver has no more (EINVAL ends every V4L2 enumeration)."""
    buffer = bytearray(packed)
    try:
        fcntl.ioctl(fd, request, buffer)
    except OSError:
        return None
    return bytes(buffer)


def _text(raw: bytes) -> str:
    return raw.split(b"\0", 1)[0].decode("utf-8", "replace")


def captures(fd: int) -> bool:
    """Whether this node captures video (a USB camera makes a second node for metadata that does not)."""
    answer = _ask(fd, VIDIOC_QUERYCAP, bytes(104))
    if answer is None:
        return False
    capabilities, device_caps = struct.unpack_from("<II", answer, 84)
    return bool((device_caps if capabilities & DEVICE_CAPS else capabilities) & CAPTURE)


def _rates(fd: int, fourcc: int, width: int, height: int) -> tuple[float, ...]:
    rates: list[float] = []
    for index in range(64):
        answer = _ask(fd, VIDIOC_ENUM_FRAMEINTERVALS, struct.pack("<5I", index, fourcc, width, height, 0) + bytes(32))
        if answer is None:
            break
        kind, numerator, denominator = struct.unpack_from("<3I", answer, 16)
        if numerator:  # an interval: frames per second is its inverse
            rates.append(round(denominator / numerator, 2))
        if kind != DISCRETE:  # a range: its fastest end is the first fraction
            break
    return tuple(sorted(set(rates), reverse=True))


def modes(fd: int) -> list[Mode]:
    """Every (pixel format, size) the device captures, with its frame rates."""
    found: list[Mode] = []
    for format_index in range(32):
        answer = _ask(fd, VIDIOC_ENUM_FMT, struct.pack("<3I", format_index, CAPTURE, 0) + bytes(52))
        if answer is None:
            break
        fourcc = struct.unpack_from("<I", answer, 44)[0]
        name = fourcc.to_bytes(4, "little").decode("ascii", "replace").strip()
        for size_index in range(64):
            size = _ask(fd, VIDIOC_ENUM_FRAMESIZES, struct.pack("<3I", size_index, fourcc, 0) + bytes(32))
            if size is None:
                break
            kind, width, height = struct.unpack_from("<3I", size, 8)
            if kind != DISCRETE:  # stepwise: its largest size stands for the range
                width, height = struct.unpack_from("<I", size, 16)[0], struct.unpack_from("<I", size, 28)[0]  # max_width, max_height
            found.append(Mode(name, width, height, _rates(fd, fourcc, width, height)))
            if kind != DISCRETE:
                break
    return found


def query(path: str) -> list[Mode] | None:
    """The modes of the device at `path`, or None when it is not a capture device (or cannot be opened)."""
    try:
        fd = os.open(path, os.O_RDWR | os.O_NONBLOCK)
    except OSError:
        return None
    try:
        return modes(fd) if captures(fd) else None
    finally:
        os.close(fd)
