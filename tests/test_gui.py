"""The real GUI: the simulation node in GUI mode under `dora run`, on an Xvfb display.

Screenshots (ImageMagick `import`) before and after a joint_cmd show that the arm
is drawn and that it moved, in PyBullet's window and in MuJoCo's. The arm is the only
yellow thing in the scene (its 3D-printed parts, rgba 1.0 0.82 0.12 in the URDF and the
MJCF); PyBullet's floor is a blue-white checker and its sky lavender, MuJoCo's floor
grey-blue, so yellow pixels are the arm.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import time

import pytest

from so101.bodies.registry import BODIES, SIMULATED_BODIES
from so101.runtime.dataflow import dataflow_copy, write_dataflow
from tests.helpers.dataflow import ROOT, DoraRun
from tests.helpers.screen import GUI_MARKS, MIN_ARM_PIXELS, SAME_FRAME_OVERLAP, arm_pixels, overlap, screenshot, settled_arm

pytestmark = GUI_MARKS

SENDER = ROOT / "tests" / "nodes" / "joint_cmd_sender.py"
# shoulder_pan to 90°: the arm swings to the other side of its base, in full view of the default camera.
COMMAND_DEG = "90 0 0 0 0"
MAX_OVERLAP_AFTER_MOVE = 0.5  # intersection over union of the arm's pixels before and after
WINDOW_TITLES = {"pybullet": "Bullet Physics", "mujoco": "MuJoCo"}


def gui_dataflow(tmp_path, trigger_file, body="pybullet"):
    """A body's dataflow file with the simulation in GUI mode and the test's sender in the prompt's place
    (same id and output, so the simulation's joint_cmd input stays as the file has it)."""
    descriptor = dataflow_copy({"SO101_MODE": "gui", "SO101_LANG": "en"}, BODIES[body].dataflow_file)
    for node in descriptor["nodes"]:
        if node["id"] == "keyboard_control":
            node["path"] = str(SENDER)
            node["inputs"] = {"tick": "dora/timer/millis/50"}
            node["env"] = {"TRIGGER_FILE": str(trigger_file), "JOINT_CMD": COMMAND_DEG}
    return write_dataflow(descriptor, tmp_path / "dataflow.yml")


@pytest.mark.parametrize("body", SIMULATED_BODIES)
def test_arm_is_drawn_and_moves_in_the_gui_window(tmp_path, xvfb_display, body):
    empty = arm_pixels(screenshot(xvfb_display, tmp_path / "empty.png"))
    assert empty.sum() == 0  # the bare X screen has nothing yellow: a yellow pixel later is the arm

    trigger = tmp_path / "send-now"
    dora = DoraRun(gui_dataflow(tmp_path, trigger, body), tmp_path / "dora.log", stop_after_s=300, DISPLAY=xvfb_display)
    try:
        dora.wait_for("SO-101 loaded", timeout_s=120)
        assert "(GUI mode" in dora.log()
        # The window loads in its own process after the physics: on a busy CI machine MuJoCo's
        # showed no arm for the minute after "loaded", so the screenshots start when it says it shows.
        dora.wait_for("window open: it shows the arm", timeout_s=120)
        before = settled_arm(xvfb_display, tmp_path / "before.png", lambda m: m.sum() >= MIN_ARM_PIXELS)
        assert before.sum() >= MIN_ARM_PIXELS, f"the arm is not drawn: {before.sum()} yellow pixels"

        trigger.touch()
        dora.wait_for("sent joint_cmd 1")
        dora.wait_for("all joint targets -> [90.0, 0.0, 0.0, 0.0, 0.0]°")
        after = settled_arm(
            xvfb_display, tmp_path / "after.png",
            lambda m: m.sum() >= MIN_ARM_PIXELS and overlap(before, m) < MAX_OVERLAP_AFTER_MOVE,
        )
    finally:
        exit_code = dora.stop()
    assert after.sum() >= MIN_ARM_PIXELS, f"the arm is not drawn after the command: {after.sum()} yellow pixels"
    assert overlap(before, after) < MAX_OVERLAP_AFTER_MOVE, "the arm did not move on screen"
    assert exit_code == 0, dora.log()[-3000:]
    assert "Traceback" not in dora.log()


@pytest.mark.skipif(shutil.which("xdotool") is None, reason="xdotool is not installed (package xdotool)")
@pytest.mark.parametrize("body", SIMULATED_BODIES)
def test_killed_gui_window_ends_the_simulation_and_is_not_reopened(tmp_path, xvfb_display, body):
    """A window manager's forced close cuts the X connection, and the window's process ends
    (PyBullet's Xlib: "XIO: fatal IO error"); the simulation notices within a frame, says so
    and exits 1.

    Under the `never` restart policy dora reports it and does not start the
    simulation again; a restart policy would reopen the window the person closed.
    (Here the sender's timer keeps the dataflow up until Ctrl-C; in dataflow.yml
    the prompt is the only other node.)
    """
    display_env = dict(os.environ, DISPLAY=xvfb_display)
    dora = DoraRun(gui_dataflow(tmp_path, tmp_path / "unused", body), tmp_path / "dora.log", stop_after_s=300,
                   DISPLAY=xvfb_display)
    try:
        # The window opens in its own process, while the physics already runs.
        dora.wait_for("window open: it shows the arm", timeout_s=120)
        windows = subprocess.run(
            ["xdotool", "search", "--name", WINDOW_TITLES[body]], capture_output=True, text=True,
            env=display_env, timeout=60,
        ).stdout.split()
        assert len(windows) == 1, windows
        subprocess.run(["xdotool", "windowkill", windows[0]], check=True, env=display_env, timeout=30)
        dora.wait_for("[simulation] stopping: the window was closed")
        dora.wait_for("simulation: daemon exited")
        time.sleep(2)  # room for a restart, were one configured
    finally:
        exit_code = dora.stop()
    log = dora.log()
    assert exit_code == 1
    assert "Node `simulation` failed" in log
    assert log.count("simulation: spawner spawned node") == 1, "the simulation was started again"
    assert "restarting node" not in log


@pytest.mark.skipif(shutil.which("xdotool") is None, reason="xdotool is not installed (package xdotool)")
def test_the_window_keeps_pybullets_camera_controls(tmp_path, xvfb_display):
    """The window is a mirror in its own process, and still PyBullet's own: Ctrl + left drag
    turns the camera, the wheel zooms, a plain left drag does neither (the arm does not move)."""
    display_env = dict(os.environ, DISPLAY=xvfb_display)

    def xdotool(*args):
        subprocess.run(["xdotool", *args], check=True, env=display_env, timeout=30)

    dora = DoraRun(gui_dataflow(tmp_path, tmp_path / "unused"), tmp_path / "dora.log", stop_after_s=300,
                   DISPLAY=xvfb_display)
    try:
        dora.wait_for("window open: it shows the arm", timeout_s=120)
        before = settled_arm(xvfb_display, tmp_path / "before.png", lambda m: m.sum() >= MIN_ARM_PIXELS)
        # A plain left drag, the course's "rotate", leaves the camera where it is.
        xdotool("mousemove", "500", "400")
        xdotool("mousedown", "1")
        for step in range(1, 21):
            xdotool("mousemove", str(500 + 12 * step), "400")
            time.sleep(0.05)
        xdotool("mouseup", "1")
        time.sleep(1.5)  # the window takes the mouse's events at least 4 times a second
        plain_drag = arm_pixels(screenshot(xvfb_display, tmp_path / "plain-drag.png"))
        xdotool("mousemove", "500", "400")
        xdotool("keydown", "ctrl")
        xdotool("mousedown", "1")
        for step in range(1, 21):
            xdotool("mousemove", str(500 + 12 * step), "400")
            time.sleep(0.05)
        xdotool("mouseup", "1")
        xdotool("keyup", "ctrl")
        turned = settled_arm(xvfb_display, tmp_path / "turned.png", lambda m: overlap(before, m) < MAX_OVERLAP_AFTER_MOVE)
        for _ in range(3):
            xdotool("click", "5")  # wheel down: zoom out
        zoomed = settled_arm(xvfb_display, tmp_path / "zoomed.png", lambda m: m.sum() < 0.7 * turned.sum())
    finally:
        exit_code = dora.stop()
    assert before.sum() >= MIN_ARM_PIXELS
    assert overlap(before, plain_drag) > SAME_FRAME_OVERLAP, "a plain left drag moved the camera"
    assert overlap(before, turned) < MAX_OVERLAP_AFTER_MOVE, "Ctrl + drag did not turn the camera"
    assert zoomed.sum() < 0.7 * turned.sum(), "the wheel did not zoom out"
    assert exit_code == 0, dora.log()[-3000:]
