"""A window that shows a picture with lines of text over its foot (glfw, MuJoCo's own drawing of pixels
and text): `so101 cameras --align`'s overlay where there is a display."""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
import numpy.typing as npt

RgbImage = npt.NDArray[np.uint8]


class WindowError(Exception):
    """A window that cannot open; str() is one line."""


def ascii_line(text: str) -> str:
    """A line MuJoCo's window font can draw (it has ASCII only)."""
    return text.replace("°", " deg").encode("ascii", "replace").decode("ascii")


class PictureWindow:
    """A glfw window showing a picture, with lines of text over its foot; `q` or Esc closes it. In this
    thread, beside MuJoCo's own (invisible) glfw context: each draw makes its window's context current."""

    def __init__(self, title: str, width: int, height: int):
        import glfw
        import mujoco

        self._glfw: Any = glfw
        self._mujoco = mujoco
        if not glfw.init():
            raise WindowError("glfw cannot start")
        glfw.default_window_hints()  # MuJoCo's offscreen context leaves "invisible" as the hint
        glfw.window_hint(glfw.RESIZABLE, glfw.FALSE)
        self.window: Any = glfw.create_window(width, height, title, None, None)
        if not self.window:
            raise WindowError("glfw cannot open a window on this display")
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
