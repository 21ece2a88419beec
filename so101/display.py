"""Choosing GUI or DIRECT: a headless machine must never die on "cannot connect to X server"."""

from __future__ import annotations

import os
import sys
from pathlib import Path

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
