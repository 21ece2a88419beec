"""GUI or DIRECT: a headless machine gets DIRECT with a notice, never an X error."""

from __future__ import annotations

import pytest

from so101.runtime.display import DisplayError, display_available, resolve_mode
from tests.helpers.dataflow import unused_display


def test_auto_without_display_is_direct_with_a_notice():
    mode, notice = resolve_mode("auto", environ={}, platform="linux")
    assert mode == "direct"
    assert notice is not None and "\n" not in notice
    assert "DIRECT" in notice and "DISPLAY" in notice


def test_auto_with_an_empty_display_is_direct():
    assert resolve_mode("auto", environ={"DISPLAY": ""}, platform="linux")[0] == "direct"


def test_auto_with_a_local_display_whose_socket_is_gone_is_direct():
    # A stale DISPLAY (e.g. an Xvfb that has exited) would make PyBullet's X client kill the process.
    environ = {"DISPLAY": unused_display() + ".0"}
    assert display_available(environ, "linux") is False
    mode, notice = resolve_mode("auto", environ=environ, platform="linux")
    assert mode == "direct" and notice


def test_auto_with_a_remote_display_is_gui():
    # ssh -X sets DISPLAY=localhost:10.0: a TCP display we cannot check by a socket file.
    assert resolve_mode("auto", environ={"DISPLAY": "localhost:10.0"}, platform="linux") == ("gui", None)


def test_gui_without_display_is_a_clear_error():
    with pytest.raises(DisplayError) as caught:
        resolve_mode("gui", environ={}, platform="linux")
    message = str(caught.value)
    assert "\n" not in message
    assert "display" in message and "direct" in message


def test_direct_never_needs_a_display():
    assert resolve_mode("direct", environ={}, platform="linux") == ("direct", None)


@pytest.mark.parametrize("requested", ["auto", "gui"])
def test_macos_always_has_a_window(requested):
    assert resolve_mode(requested, environ={}, platform="darwin") == ("gui", None)


def test_unknown_mode_names_the_accepted_ones():
    with pytest.raises(ValueError) as caught:
        resolve_mode("headless", environ={}, platform="linux")
    assert "'headless'" in str(caught.value)
    assert "auto, gui, direct" in str(caught.value)
