"""Choosing GUI or DIRECT: a headless machine must never die on "cannot connect to X server"."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

from so101.runtime.processes import stop_process

MODES = ("auto", "gui", "direct")
MODE_ENV_VAR = "SO101_MODE"


class DisplayError(RuntimeError):
    """A window was asked for where none can open."""


def display_available(environ=os.environ, platform: str = sys.platform) -> bool:
    """Whether a GUI window can open: always on macOS/Windows; on Linux only with a reachable X display."""
    if platform in ("darwin", "win32"):
        return True
    display = environ.get("DISPLAY", "")
    if not display:
        return False
    if display.startswith(":"):
        # A local display `:N` must have its socket, or PyBullet's X client exits the process.
        number = display[1:].split(".")[0]
        return Path(f"/tmp/.X11-unix/X{number}").exists()
    return True


def choose_mujoco_gl(environ=os.environ) -> None:
    """Offscreen drawing without a display needs an OpenGL back end: EGL, with Mesa's software
    renderer where there is no GPU. MuJoCo reads MUJOCO_GL when it is imported, so whoever imports
    mujoco calls this first."""
    if not display_available(environ):
        environ.setdefault("MUJOCO_GL", "egl")


def resolve_mode(requested: str, environ=os.environ, platform: str = sys.platform) -> tuple[str, str | None]:
    """'auto' | 'gui' | 'direct' -> ('gui' | 'direct', notice or None)."""
    if requested not in MODES:
        raise ValueError(f"unknown simulation mode {requested!r}; use one of: {', '.join(MODES)}")
    if requested == "gui" and not display_available(environ, platform):
        raise DisplayError(
            "GUI mode needs a display, and none is reachable (DISPLAY is not set or its X server is gone): "
            "use mode auto or direct, or run under xvfb-run"
        )
    if requested != "auto":
        return requested, None
    if display_available(environ, platform):
        return "gui", None
    return "direct", "no display found (DISPLAY is not set or not reachable): running headless in DIRECT mode"


@contextlib.contextmanager
def virtual_display(log_path: Path | None = None, size: str = "1280x800x24"):
    """A fresh Xvfb server on a display number it picks itself (-displayfd): yields ":N", stops it after.

    Raises DisplayError, with Xvfb's own last words, when it is not installed or does not start.
    """
    if shutil.which("Xvfb") is None:
        raise DisplayError("Xvfb is not installed (Debian package xvfb)")
    read_end, write_end = os.pipe()
    log = open(log_path, "wb") if log_path else subprocess.DEVNULL
    try:
        server = subprocess.Popen(
            ["Xvfb", "-displayfd", str(write_end), "-screen", "0", size, "-nolisten", "tcp"],
            pass_fds=(write_end,), stdout=subprocess.DEVNULL, stderr=log, start_new_session=True,
        )
    finally:
        os.close(write_end)
    try:
        with os.fdopen(read_end, "rb") as reader:
            number = reader.readline().strip()  # Xvfb writes the number once it listens, or exits
        if not number:
            said = Path(log_path).read_text(errors="replace")[-500:] if log_path else ""
            raise DisplayError(f"Xvfb did not start{': ' + said if said else ''}")
        yield f":{number.decode()}"
    finally:
        stop_process(server, 10, first_signal=signal.SIGTERM)
        if not isinstance(log, int):  # a file of ours, not subprocess.DEVNULL
            log.close()
