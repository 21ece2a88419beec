"""`so101 cameras --align NAME`: a real camera lined up with the simulated one, by hand, by eye.

A few times a second: the arm's six joint angles read from its bus (read only: torque off, moved by
hand, no goal ever written), the simulated camera's picture of the arm at those angles drawn as a mask
(so101.bodies.task_cameras), and the camera's newest live picture with that mask over it: tinted, its
outline drawn. A person moves the camera until the real arm fills the outline. The overlay shows in a
window where there is a display (glfw, MuJoCo's own drawing of pixels and text) and always in a browser
(a viser page). With a fitted camera file (`--fitted`, from `so101 cameras --fit`) it also says in words
which way to move the camera (so101.camera_pose.moves).

Every way out (Ctrl-C, SIGTERM, the window closed, `q`, a failure) switches torque off and closes the
camera, and says so in one line.
"""

from __future__ import annotations

import contextlib
import io
import os
import signal
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import numpy.typing as npt

from so101.bodies.camera_file import CameraFile
from so101.cameras.capture import Capturing, VideoSource
from so101.cameras.sources import DEFAULT_CAMERA_FPS, capture_source, is_device, source_problem
from so101.feetech.bus import BusError, BusLost, FeetechBus
from so101.feetech.calibration import (
    MOTOR_IDS, MOTOR_NAMES, CalibrationError, load_calibration, parse_joint_signs, steps_to_deg,
)
from so101.feetech.checks import check_calibration_on_servos, check_servos_answer
from so101.camera_pose.overlay import overlay_picture, outline_on_edges, agreement_text, window_size, ascii_line, window_lines, panel_markdown
from so101.camera_pose.moves import move_in_words
from so101.runtime.display import choose_mujoco_gl, display_available

RgbImage = npt.NDArray[np.uint8]

REFRESH_HZ = 5.0  # enough for a hand moving a camera; each refresh draws one mask (~20 ms in software)
FIRST_PICTURE_S = 10.0  # a camera that gives no picture in this long gives none
CAMERA_ASKED_SIZE = (640, 480)  # what a device is asked for: LeRobot's SO-101 guide's cameras
# A read that fails now and then passes; this many in a row (about two seconds) is an arm gone.
FAILED_READS_AT_MOST = 10
TORQUE_OFF_READS = 3
# The task whose front camera is drawn, and its objects' object_state far off every picture (cube_to_box's:
# the cube's centre and quaternion, the box's position).
ALIGN_TASK = "cube_to_box"
OBJECTS_AWAY = (5.0, 5.0, 0.0125, 0.0, 0.0, 0.0, 1.0, 5.0, 5.0, 0.0)
JOINT_SIGNS_ENV_VAR = "SO101_JOINT_SIGNS"


class AlignError(Exception):
    """What stops the alignment before or while it runs; str() is one line for the person."""



# -- the arm, read only --------------------------------------------------------------------------------


class ArmReader:
    """The SO-101 on `port`, with the calibration at `calibration_path`, read only: torque switched off at
    start (it is moved by hand) and again at `close()`, whatever was on; `read_deg()` gives the six joint
    angles (the URDF's degrees). AlignError in one line when it cannot start."""

    def __init__(self, port: str, calibration_path: Path, joint_signs: tuple[int, ...] = (1,) * 6):
        self.port = port
        try:
            calibration = load_calibration(calibration_path)
        except CalibrationError as error:
            raise AlignError(str(error)) from None
        self._motors = [calibration[name] for name in MOTOR_NAMES]
        self._signs = joint_signs
        self.failed_reads = 0
        self.bus: FeetechBus | None = None
        try:
            bus = self.bus = FeetechBus(port).open()
            check_servos_answer(bus)
            check_calibration_on_servos(bus, self._motors, str(calibration_path), "arm",
                                        "calibrate it (`so101 calibrate`) or give its own file")
            bus.sync_write("Torque_Enable", {servo_id: 0 for servo_id in MOTOR_IDS})
        except (BusError, CalibrationError) as error:
            self.close()
            raise AlignError(str(error)) from None
        except BaseException:
            self.close()
            raise

    def read_deg(self) -> tuple[float, ...] | None:
        """The six angles now; None when this read failed. AlignError once the arm is gone (its port lost,
        or FAILED_READS_AT_MOST reads failed in a row)."""
        if self.bus is None:
            return None
        try:
            present = self.bus.sync_read("Present_Position", MOTOR_IDS)
        except BusLost as error:
            raise AlignError(f"the arm on {self.port} is gone ({error})") from None
        except BusError as error:
            self.failed_reads += 1
            if self.failed_reads >= FAILED_READS_AT_MOST:
                raise AlignError(f"the arm on {self.port} stopped answering ({error}; {self.failed_reads} reads "
                                 "failed in a row)") from None
            return None
        self.failed_reads = 0
        return tuple(steps_to_deg(index, present[servo_id], motor, sign)
                     for index, (servo_id, motor, sign) in enumerate(zip(MOTOR_IDS, self._motors, self._signs)))

    def close(self) -> str | None:
        """Torque off on every servo (confirmed by reading it back), then the port closed; None when done,
        else the line that says torque could not be confirmed off. Safe twice."""
        bus, self.bus = self.bus, None
        if bus is None:
            return None
        try:
            bus.sync_write("Torque_Enable", {servo_id: 0 for servo_id in MOTOR_IDS})
            # An "on" is read again before it is believed: Ctrl-C can leave an old reply on the line.
            for _ in range(TORQUE_OFF_READS):
                if not any(bus.sync_read("Torque_Enable", MOTOR_IDS).values()):
                    return None
                time.sleep(0.02)
            return "a servo still reports torque on: switch the arm's power off"
        except BusError as error:
            return f"could not confirm torque off ({error}): switch the arm's power off"
        finally:
            bus.close()


# -- the window and the browser page -------------------------------------------------------------------


class AlignWindow:
    """A glfw window showing the overlay, with lines of text over its foot; `q` or Esc closes it. In this
    thread, beside MuJoCo's own (invisible) glfw context: each draw makes its window's context current."""

    def __init__(self, title: str, width: int, height: int):
        import glfw
        import mujoco

        self._glfw: Any = glfw
        self._mujoco = mujoco
        if not glfw.init():
            raise AlignError("glfw cannot start")
        glfw.default_window_hints()  # MuJoCo's offscreen context leaves "invisible" as the hint
        glfw.window_hint(glfw.RESIZABLE, glfw.FALSE)
        self.window: Any = glfw.create_window(width, height, title, None, None)
        if not self.window:
            raise AlignError("glfw cannot open a window on this display")
        self.closed_by: str | None = None
        glfw.make_context_current(self.window)
        glfw.swap_interval(0)
        # MuJoCo's drawing of pixels and text needs a context of its own: an empty model's is the least.
        self._context = mujoco.MjrContext(mujoco.MjModel.from_xml_string("<mujoco/>"),
                                          mujoco.mjtFontScale.mjFONTSCALE_100)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_WINDOW, self._context)
        glfw.set_key_callback(self.window, self._key)

    def _key(self, window: Any, key: int, scancode: int, action: int, mods: int) -> None:
        glfw = self._glfw
        if action == glfw.PRESS and key in (glfw.KEY_Q, glfw.KEY_ESCAPE):
            self.closed_by = "q pressed"
            glfw.set_window_should_close(window, True)

    def show(self, picture: RgbImage, lines: Sequence[str]) -> None:
        import cv2

        glfw, mujoco = self._glfw, self._mujoco
        glfw.make_context_current(self.window)
        width, height = glfw.get_framebuffer_size(self.window)
        shown = picture
        if (picture.shape[1], picture.shape[0]) != (width, height):
            shown = np.asarray(cv2.resize(picture, (width, height), interpolation=cv2.INTER_AREA), np.uint8)
        viewport = mujoco.MjrRect(0, 0, width, height)
        # OpenGL's rows go from the bottom up.
        mujoco.mjr_drawPixels(np.ascontiguousarray(shown[::-1]).ravel(), None, viewport, self._context)
        mujoco.mjr_overlay(mujoco.mjtFont.mjFONT_NORMAL, mujoco.mjtGridPos.mjGRID_BOTTOMLEFT, viewport,
                           "\n".join(ascii_line(line) for line in lines), "", self._context)
        glfw.swap_buffers(self.window)

    def wait(self, seconds: float) -> bool:
        """Events handled for up to `seconds`; False once the window is closed (its button, q, Esc)."""
        glfw = self._glfw
        if seconds > 0:
            glfw.wait_events_timeout(seconds)
        else:
            glfw.poll_events()
        if glfw.window_should_close(self.window):
            self.closed_by = self.closed_by or "window closed"
            return False
        return True

    def close(self) -> None:
        if self.window is not None:
            self._glfw.make_context_current(self.window)
            self._context.free()
            self._glfw.make_context_current(None)
            self._glfw.destroy_window(self.window)
            self._glfw.poll_events()
            self.window = None


class AlignPage:
    """A viser page on host:port with the overlay and what it means: the browser view. `port` taken, viser
    takes the next free one: `address` says which."""

    def __init__(self, host: str, port: int, picture: RgbImage):
        import logging

        import viser

        from so101.web.settings import page_address

        logging.getLogger("websockets.server").setLevel(logging.CRITICAL)  # a probe's closed connection is no error
        with contextlib.redirect_stdout(io.StringIO()):  # viser's banner: the address is said in one line instead
            self.server: Any = viser.ViserServer(host=host, port=port, verbose=False)
        self.server.gui.configure_theme(control_width="large", show_share_button=False)
        self._text = self.server.gui.add_markdown("")
        self._picture = self.server.gui.add_image(picture, label="overlay", format="jpeg", jpeg_quality=85)
        self.address = page_address(host, int(self.server.get_port()))

    def show(self, picture: RgbImage, text: str) -> None:
        with self.server.atomic():
            self._picture.image = picture
            if text != self._text.content:
                self._text.content = text

    def close(self) -> None:
        server, self.server = self.server, None
        if server is not None:
            with contextlib.redirect_stdout(io.StringIO()):  # "(viser) Server stopped"
                server.stop()


# -- the loop ------------------------------------------------------------------------------------------


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
    """The size of the first picture `source` gives (within FIRST_PICTURE_S); AlignError otherwise."""
    problem = device_problem(source) if is_device(source) else video_file_problem(str(source))
    if problem is not None:
        raise AlignError(f"camera {name}: {where}: {problem}")
    probe = VideoSource(source, None, CAMERA_ASKED_SIZE if is_device(source) else None, DEFAULT_CAMERA_FPS)
    why = probe.open()
    if why is not None:
        raise AlignError(f"camera {name}: {where}: {why}")
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
    raise AlignError(f"camera {name}: {where} gave no picture (a camera in use by another program, or a video "
                     "file with none?)")


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
        page = AlignPage(request.web_host, request.web_port, overlay_picture(np.zeros((height, width, 3), np.uint8),
                                                                             arm_pixels))
        closing.append(page.close)
        say(f"browser view: {page.address}")
        window = None
        if request.window and display_available():
            try:
                window = AlignWindow(f"so101 cameras --align {name}", *window_size(width, height))
            except AlignError as error:
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
    except AlignError as error:
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


def _loop(request: AlignRequest, arm: ArmReader, capturing: Capturing, cameras: Any, page: AlignPage,
          window: AlignWindow | None, words: str | None, say: Callable[[str], None], signals: _Signals) -> str:
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

