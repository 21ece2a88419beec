"""`so101 cameras --align NAME`: a real camera lined up with the simulated one, by hand, by eye.

A few times a second: the arm's six joint angles read from its bus (read only: torque off, moved by
hand, no goal ever written), the simulated camera's picture of the arm at those angles drawn as a mask
(so101.bodies.task_cameras), and the camera's newest live picture with that mask over it: tinted, its
outline drawn (so101.camera_pose.overlay). A person moves the camera until the real arm fills the outline.
The overlay shows in a window where there is a display (so101.gui.picture_window) and always in a browser
(so101.web.picture_page); the arm is read by so101.feetech.arm_reader, the camera tried first by
so101.cameras.probe. With a fitted camera file (`--fitted`, from `so101 cameras --fit`) it also says in words
which way to move the camera (so101.camera_pose.moves).

Every way out (Ctrl-C, SIGTERM, the window closed, `q`, a failure) switches torque off and closes the
camera, and says so in one line.
"""

from __future__ import annotations

import os
import signal
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from so101.bodies.camera_file import CameraFile
from so101.camera_pose.moves import move_in_words
from so101.camera_pose.overlay import (
    agreement_text, outline_on_edges, overlay_picture, panel_markdown, window_lines, window_size,
)
from so101.cameras.capture import Capturing, VideoSource
from so101.cameras.probe import CAMERA_ASKED_SIZE, ProbeError, first_picture
from so101.cameras.sources import DEFAULT_CAMERA_FPS, capture_source, is_device, source_problem
from so101.feetech.arm_reader import ArmReader, ArmReaderError
from so101.feetech.calibration import MOTOR_IDS, parse_joint_signs
from so101.gui.picture_window import PictureWindow, WindowError
from so101.runtime.display import choose_mujoco_gl, display_available
from so101.web.picture_page import PicturePage

REFRESH_HZ = 5.0  # enough for a hand moving a camera; each refresh draws one mask (~20 ms in software)
# The task whose front camera is drawn, and its objects' object_state far off every picture (cube_to_box's:
# the cube's centre and quaternion, the box's position).
ALIGN_TASK = "cube_to_box"
OBJECTS_AWAY = (5.0, 5.0, 0.0125, 0.0, 0.0, 0.0, 1.0, 5.0, 5.0, 0.0)
JOINT_SIGNS_ENV_VAR = "SO101_JOINT_SIGNS"


class AlignError(Exception):
    """What stops the alignment before or while it runs; str() is one line for the person."""


@dataclass(frozen=True)
class AlignRequest:
    """What `so101 cameras --align` was asked: camera `name` (front) seen by `source`, the arm on `port` with
    `calibration`, the simulated camera at `simulated` (`simulated_from` says where that came from), the
    real camera's fitted file (or None), the browser page's host and port, and whether to open a window."""

    name: str
    source: str
    port: str
    calibration: Path
    simulated: CameraFile
    simulated_from: str
    fitted: CameraFile | None
    web_host: str
    web_port: int
    window: bool = True


class _Stop(Exception):
    """A signal asked the alignment to end (its name)."""


class _Signals:
    """Ctrl-C, SIGTERM and SIGHUP, noted rather than raised: an exception thrown into whatever runs (the browser
    page's server, a picture's capture) can be caught there and lost; the loop asks between refreshes."""

    NAMES = {signal.SIGINT: "Ctrl-C", signal.SIGTERM: "SIGTERM", signal.SIGHUP: "SIGHUP"}

    def __init__(self) -> None:
        self.caught: str | None = None
        self._previous = {signum: signal.signal(signum, self._note) for signum in self.NAMES}

    def _note(self, signum: int, frame: object) -> None:
        self.caught = self.caught or self.NAMES[signal.Signals(signum)]

    def check(self) -> None:
        """_Stop if a signal came."""
        if self.caught is not None:
            raise _Stop(self.caught)

    def restore(self) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)


def run_align(request: AlignRequest, say: Callable[[str], None] = print) -> int:
    """The alignment until Ctrl-C, SIGTERM, the window's close or `q`: 0 then, torque off. AlignError in one
    line for what stops it before it starts (nothing left on); a failure while it runs is said in one line, 1."""
    name = request.name
    problem = source_problem(capture_source(request.source))
    if problem is not None:
        raise AlignError(f"--camera {name}={request.source}: {problem}")
    try:
        signs = parse_joint_signs(joint_signs_setting())
    except ValueError as error:
        raise AlignError(str(error)) from None
    source = capture_source(request.source)
    signals = _Signals()
    arm: ArmReader | None = None
    capturing: Capturing | None = None
    closing: list[Callable[[], None]] = []
    outcome, code = "stopped", 0
    running = False  # the overlay loop began: a failure from now on is the run's, not the request's
    failure: str | None = None
    try:
        # The camera first: a camera that gives no picture is said before the arm is touched.
        width, height = first_picture(source, request.source, name)
        signals.check()
        arm = ArmReader(request.port, request.calibration, signs)
        say(f"arm on {request.port}: read only, torque off: move it by hand")
        say(f"camera {name}: {request.source}, {width}x{height}")
        # A file that ended plays again, quietly; a device that stops or comes back is said.
        capturing = Capturing(VideoSource(source, None, CAMERA_ASKED_SIZE if is_device(source) else None,
                                          DEFAULT_CAMERA_FPS), name, request.source,
                              say if is_device(source) else (lambda line: None), retry_s=0.2)
        capturing.start()
        choose_mujoco_gl()
        from so101.bodies.task_cameras import TaskCameras
        from so101.tasks import TASKS

        try:
            # A task's cameras, for a task's front camera stands where a camera file puts it; the task's objects
            # moved off every picture once (a real scene has its own), so that none hides a part of the arm.
            cameras = TaskCameras(TASKS[ALIGN_TASK], looks="fixed", poses={name: request.simulated},
                                  log=lambda line: None)
            closing.append(cameras.close)
            angles = arm.read_deg() or (0.0,) * len(MOTOR_IDS)
            cameras.draw(angles, OBJECTS_AWAY, width, height, wrist=False)
            arm_pixels = cameras.arm_mask(angles, cameras.front_camera(), width, height)
        except (RuntimeError, ValueError) as error:
            raise AlignError(f"the simulated camera cannot draw: {error}") from None
        say(f"simulated {name} camera: {request.simulated_from}")
        words = None
        if request.fitted is not None:
            words = move_in_words(request.fitted, request.simulated)
            say(f"to stand where the simulated {name} camera stands: {words}")
        page = PicturePage(request.web_host, request.web_port, overlay_picture(np.zeros((height, width, 3), np.uint8),
                                                                             arm_pixels))
        closing.append(page.close)
        say(f"browser view: {page.address}")
        window = None
        if request.window and display_available():
            try:
                window = PictureWindow(f"so101 cameras --align {name}", *window_size(width, height))
            except WindowError as error:
                say(f"no window ({error}): the browser view shows the overlay")
            else:
                closing.append(window.close)
                say("window open: move the camera until the real arm fills the outline; q or Esc ends")
        elif request.window:
            say("no display (DISPLAY is not set or not reachable): no window; the browser view shows the overlay")
        running = True
        outcome = _loop(request, arm, capturing, cameras, page, window, words, say, signals)
    except _Stop as stop:
        outcome = f"stopped ({stop})"
    except (AlignError, ArmReaderError, ProbeError) as error:
        failure = str(error)
    finally:
        signals.restore()
        for close in reversed(closing):
            close()
        if capturing is not None:
            capturing.stop()
        torque = arm.close() if arm is not None else None
    if failure is not None and not running:
        raise AlignError(failure if torque is None else f"{failure}; {torque}")
    if failure is not None:
        outcome, code = f"stopped: {failure}", 1
    if torque is not None:
        say(f"{outcome}; {torque}; camera {name} closed")
        return 1
    say(f"{outcome}: torque off on servos 1-6, camera {name} closed")
    return code


def joint_signs_setting() -> str:
    """SO101_JOINT_SIGNS as the arm node reads it: a joint whose direction differs from the URDF's (default none)."""
    return os.environ.get(JOINT_SIGNS_ENV_VAR, "").strip() or ",".join(["1"] * len(MOTOR_IDS))


def _loop(request: AlignRequest, arm: ArmReader, capturing: Capturing, cameras: Any, page: PicturePage,
          window: PictureWindow | None, words: str | None, say: Callable[[str], None], signals: _Signals) -> str:
    """Refreshes the overlay REFRESH_HZ times a second until the window closes (what closed it, returned);
    Ctrl-C, SIGTERM or SIGHUP (asked for between refreshes) and a failure end it by raising."""
    period_s = 1.0 / REFRESH_HZ
    angles: tuple[float, ...] | None = None
    shown_first = False
    while True:
        signals.check()
        started = time.monotonic()
        angles = arm.read_deg() or angles
        if capturing.failed is not None:
            raise AlignError(capturing.failed)
        picture = capturing.latest
        if angles is not None and picture is not None:
            live = picture.rgb
            height, width = live.shape[:2]
            arm_pixels = cameras.arm_mask(angles, cameras.front_camera(), width, height)
            overlay = overlay_picture(live, arm_pixels)
            agreement = agreement_text(outline_on_edges(live, arm_pixels))
            page.show(overlay, panel_markdown(request.name, request.simulated_from, agreement, words, angles))
            if window is not None:
                window.show(overlay, window_lines(words, agreement))
            if not shown_first:
                say(f"overlay live: {agreement}; Ctrl-C ends")
                shown_first = True
        left_s = period_s - (time.monotonic() - started)
        if window is not None:
            if not window.wait(left_s):
                return f"stopped ({window.closed_by})"
        elif left_s > 0:
            time.sleep(left_s)

