"""Pictures from one real camera, or from a video file standing in for one, through OpenCV's
VideoCapture (V4L2 on Linux): each with the time it was captured. A file plays at its own frame
rate. `Capturing` runs the capture in a thread of its own, keeps the newest picture, and when the
camera stops (unplugged, a read that fails, a file that ended) says so in one line, tries it again
every second and says when it is back."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Protocol

import numpy as np
import numpy.typing as npt

from so101.cameras.sources import capture_time_s, is_device, scaled_size

RETRY_S = 1.0
# A file that fell this far behind its own rate (a stalled machine) is played on from now, not raced.
FILE_LATE_S = 1.0


@dataclass(frozen=True)
class Picture:
    rgb: npt.NDArray[np.uint8]  # (height, width, 3)
    captured_s: float  # wall clock (time.time()), as dora stamps messages
    number: int  # counted from the node's start, over reconnections


class Source(Protocol):
    """A camera as Capturing uses it (VideoSource; a test's stand-in)."""

    def open(self) -> str | None: ...  # None when it is open; else why not, briefly

    def read(self) -> tuple[npt.NDArray[np.uint8], float] | None: ...  # (RGB, captured_s), None when it stopped

    def close(self) -> None: ...


class VideoSource:
    """A device index, a /dev/videoN path or a video file, opened with OpenCV; its pictures as RGB at
    `size` (scaled where the camera gives another size of the same shape, see sources.scaled_size), a
    device asked for `capture_size` and `fps`."""

    def __init__(self, source: int | str, size: tuple[int, int] | None, capture_size: tuple[int, int] | None,
                 fps: int, clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep):
        self.source, self.size, self.capture_size, self.fps = source, size, capture_size, fps
        self.device = is_device(source)
        self._clock, self._sleep = clock, sleep
        self._capture: Any = None
        self._period_s = 0.0  # a file's frame period
        self._started_s = 0.0
        self._frames = 0
        self.given: tuple[int, int] | None = None  # what the camera gives, once it gave a picture

    def open(self) -> str | None:
        import cv2

        if self.device:
            capture = cv2.VideoCapture(self.source, cv2.CAP_V4L2) if isinstance(self.source, int) or \
                str(self.source).startswith("/dev/video") else cv2.VideoCapture(self.source)
        else:
            capture = cv2.VideoCapture(str(self.source))
        if not capture.isOpened():
            capture.release()
            return "it cannot be opened" if self.device else "OpenCV cannot open it as a video"
        if self.device:
            # MJPG first: most USB cameras give 640x480 at 30 fps only compressed over USB 2.
            capture.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter.fourcc(*"MJPG"))
            if self.capture_size:
                capture.set(cv2.CAP_PROP_FRAME_WIDTH, self.capture_size[0])
                capture.set(cv2.CAP_PROP_FRAME_HEIGHT, self.capture_size[1])
            capture.set(cv2.CAP_PROP_FPS, self.fps)
            capture.set(cv2.CAP_PROP_BUFFERSIZE, 1)  # the newest frame, not one queued behind others
        else:
            rate = capture.get(cv2.CAP_PROP_FPS)
            self._period_s = 1.0 / rate if rate and rate > 0 else 1.0 / self.fps
        self._capture, self._started_s, self._frames = capture, self._clock(), 0
        return None

    def read(self) -> tuple[npt.NDArray[np.uint8], float] | None:
        import cv2

        if self._capture is None:
            return None
        if not self.device:  # at the file's own rate: frame n is due n periods after the first
            due_s = self._started_s + self._frames * self._period_s
            wait_s = due_s - self._clock()
            if wait_s > 0:
                self._sleep(wait_s)
            elif -wait_s > FILE_LATE_S:
                self._started_s, self._frames = self._clock(), 0
        ok, bgr = self._capture.read()
        if not ok or bgr is None:
            return None
        self._frames += 1
        captured_s = capture_time_s(time.time(), time.monotonic(), self._capture.get(cv2.CAP_PROP_POS_MSEC)) \
            if self.device else time.time()
        rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        self.given = (rgb.shape[1], rgb.shape[0])
        if self.size is not None:
            target = scaled_size(self.given, self.size)  # ValueError for another shape
            if target is not None:
                # INTER_AREA: smaller pictures average their pixels (no aliasing); larger ones interpolate.
                rgb = cv2.resize(rgb, target, interpolation=cv2.INTER_AREA)
        return np.ascontiguousarray(rgb), captured_s

    def close(self) -> None:
        if self._capture is not None:
            self._capture.release()
            self._capture = None


class Capturing:
    """The capture loop of one camera, in a thread: `latest` is the newest Picture (None before the
    first). `say` hears one line when the camera cannot be opened, when it stops and when it is back;
    a camera whose pictures cannot be made the asked size stops the loop, with its line in `failed`."""

    def __init__(self, source: Source, name: str, where: str, say: Callable[[str], None], retry_s: float = RETRY_S):
        self.source, self.name, self.where, self.say, self.retry_s = source, name, where, say, retry_s
        self.latest: Picture | None = None
        self.failed: str | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self.run, name=f"camera-{name}", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.source.close()

    def run(self) -> None:
        number = 0
        missing = False  # said that it stopped or cannot be opened, and not yet that it is back
        while not self._stop.is_set():
            why = self.source.open()
            if why is not None:
                if not missing:
                    self.say(f"camera {self.name}: {self.where}: {why}; trying it again every {self.retry_s:g} s")
                    missing = True
                self._stop.wait(self.retry_s)
                continue
            while not self._stop.is_set():
                try:
                    read = self.source.read()
                except ValueError as error:  # pictures of another shape than asked: no retry mends that
                    self.failed = f"camera {self.name}: {self.where}: {error}"
                    self.say(self.failed)
                    self._stop.set()
                    break
                if read is None:
                    self.say(f"camera {self.name}: {self.where} stopped (no picture came: unplugged, or the file "
                             f"ended); trying it again every {self.retry_s:g} s")
                    missing = True
                    break
                if missing:
                    self.say(f"camera {self.name}: {self.where} is back")
                    missing = False
                rgb, captured_s = read
                self.latest = Picture(rgb, captured_s, number)
                number += 1
            self.source.close()
            self._stop.wait(self.retry_s if missing else 0.0)
