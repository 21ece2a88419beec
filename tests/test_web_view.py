"""The web view in a real headless browser (bench/browser.py), every host but 127.0.0.1 unreachable:
the page draws the arm, follows a typed command, its angle text matches joint_state; a page reloaded
and then its browser killed mid-stream leave the dataflow running; `so101 teleop --web` shows the
camera and marks a recording episode. One browser at a time: five software-drawing browsers on a
small machine measure the machine, and that is `so101 bench --web`'s (the body's pace with five
viewers, pages and viewers elsewhere); no speed is asserted here."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import time

import numpy as np
import pytest
from PIL import Image

from bench.browser import CHROMIUM, Browser
from so101.runtime.cluster import free_port
from tests.helpers.dataflow import PROMPT_COMMAND, DoraRun, body_environment, prompt_env, write_test_dataflow

pytestmark = [pytest.mark.dataflow, pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (.ci/run installs it)")]

# The page's right-hand panel (angles, plot) starts about here at 1200 px wide; the arm is drawn left of it.
PANEL_LEFT_PX = 860
# The arm drawn: this many pixels of the URDF's 3d_printed yellow, lit or shaded.
ARM_PIXELS = 3000


def angle_on_page(text: str, joint: str) -> float:
    match = re.search(rf"^{joint}: (-?\d+\.\d)°$", text, re.MULTILINE)
    assert match, text[:500]
    return float(match.group(1))


def page_showing(browser: Browser, joint: str, angle_deg: float, timeout_s: float = 60) -> str:
    """The page's text once it shows `joint` within 0.5° of `angle_deg`: the arm settled there. The web
    view runs below the body's priority, so on a loaded machine the page may lag the body by seconds."""
    deadline = time.monotonic() + timeout_s
    while abs(angle_on_page(text := browser.text(), joint) - angle_deg) > 0.5:
        assert time.monotonic() < deadline, f"the page did not show {joint} at {angle_deg}° within {timeout_s} s: {text[:500]!r}"
        time.sleep(0.3)
    return text


def scene_pixels(path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"), dtype=np.int16)[:, :PANEL_LEFT_PX]


def yellow(pixels: np.ndarray) -> np.ndarray:
    red, green, blue = pixels[..., 0], pixels[..., 1], pixels[..., 2]
    return (red > 150) & (green > 110) & (blue < 120) & (red - blue > 100)


def the_arm_drawn(browser: Browser, path, timeout_s: float = 90) -> np.ndarray:
    """The scene once the arm is drawn in full (viser fades new meshes in)."""
    deadline = time.monotonic() + timeout_s
    while True:
        time.sleep(5)  # a screenshot taken while viser fades new meshes in holds the fade back: look seldom
        if (count := yellow(pixels := scene_pixels(browser.screenshot(path))).sum()) >= ARM_PIXELS:
            return pixels
        assert time.monotonic() < deadline, f"the arm was not drawn within {timeout_s} s ({count} yellow pixels): {path}"


def test_the_page_draws_the_arm_follows_0_90_and_outlives_a_reload_and_its_browser(tmp_path):
    record_file = tmp_path / "joint_state.json"
    web_port = free_port()
    dataflow = write_test_dataflow(tmp_path, {"SO101_LANG": "en"}, record_file=record_file,
                                   web_env={"SO101_WEB_PORT": str(web_port)})
    dora = DoraRun(dataflow, tmp_path / "dora.log", stop_after_s=300)
    browser = prompt = None
    try:
        dora.wait_for(f"web view: http://127.0.0.1:{web_port}/", timeout_s=60)
        browser = Browser(free_port())
        browser.open(f"http://127.0.0.1:{web_port}/")
        browser.wait_for_text("shoulder_pan: 0.0°")
        # In this headless Chromium, viser's scene left at rest from the start stayed mid-fade-in (a
        # browser with a screen draws it at once: checked under Xvfb); a first move makes it draw, so
        # "before" is the arm at rest after one.
        prompt = subprocess.Popen(PROMPT_COMMAND, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                  text=True, env=prompt_env(tmp_path), cwd=tmp_path)
        prompt.stdin.write("0 20\n")
        prompt.stdin.flush()
        browser.wait_for_text("shoulder_pan: 20.0°")
        before = the_arm_drawn(browser, tmp_path / "before.png")
        prompt.stdin.write("0 90\n")
        prompt.stdin.close()
        assert prompt.wait(60) == 0, prompt.stdout.read()
        text = page_showing(browser, "shoulder_pan", 90.0)
        after = the_arm_drawn(browser, tmp_path / "after.png")
        if os.environ.get("SO101_WEB_SCREENSHOT"):  # docs/web_view.png: this test's own
            shutil.copyfile(tmp_path / "after.png", os.environ["SO101_WEB_SCREENSHOT"])
        browser.open(f"http://127.0.0.1:{web_port}/")  # a reload mid-stream: the new page is served the pose
        browser.wait_for_text("shoulder_pan: 9")
        browser.kill()
        killed_at = time.monotonic()
        browser = None
        time.sleep(2)
    finally:
        if browser is not None:
            browser.kill()
        if prompt is not None and prompt.poll() is None:
            prompt.kill()
        dora.stop()
    log = dora.log()
    samples = json.loads(record_file.read_text())["samples"]
    # 0 90 turned it: the scene changed where the arm was and where it is now.
    changed = (np.abs(after - before) > 40).any(axis=2)
    assert (changed & yellow(before)).sum() > 1000 and (changed & yellow(after)).sum() > 1000, changed.sum()
    # The angles shown are the body's, within 0.5° (the arm still by then).
    last_state = samples[-1][1]
    assert angle_on_page(text, "shoulder_pan") == pytest.approx(last_state[0], abs=0.5)
    # The page reloaded, then the browser killed: states go on, and the web view did not fail.
    assert any(t > killed_at + 1.5 for t, _ in samples)
    assert "Traceback" not in log and "web_view: daemon exited with code" not in log, log[-3000:]


# PyBullet's: the test above. The real arm's page is the same URDF posed by its joint_state: its replay
# runs with --web in tests/test_record_replay.py, and no browser is opened on it here (a browser costs
# this suite half a minute a page).
@pytest.mark.parametrize("body", ["mujoco"])
def test_every_body_is_shown_posed_by_its_joint_state(tmp_path, body):
    """MuJoCo's body: the URDF posed by the angles it publishes."""
    record_file = tmp_path / "joint_state.json"
    web_port = free_port()
    with body_environment(body, tmp_path) as (body_env, _):
        dataflow = write_test_dataflow(tmp_path, {"SO101_LANG": "en", **body_env}, record_file=record_file, body=body,
                                       web_env={"SO101_WEB_PORT": str(web_port)})
        dora = DoraRun(dataflow, tmp_path / "dora.log", stop_after_s=300)
        browser = None
        try:
            dora.wait_for(f"web view: http://127.0.0.1:{web_port}/", timeout_s=60)
            browser = Browser(free_port())
            browser.open(f"http://127.0.0.1:{web_port}/")
            browser.wait_for_text("shoulder_pan: ")
            prompt = subprocess.run(PROMPT_COMMAND, input="0 -60\n", capture_output=True, text=True,
                                    env=prompt_env(tmp_path), cwd=tmp_path, timeout=120)
            assert prompt.returncode == 0, prompt.stdout + prompt.stderr
            text = page_showing(browser, "shoulder_pan", -60.0)
        finally:
            if browser is not None:
                browser.kill()
            dora.stop()
    last_state = json.loads(record_file.read_text())["samples"][-1][1]
    assert angle_on_page(text, "shoulder_pan") == pytest.approx(last_state[0], abs=0.5)
    assert "Traceback" not in dora.log(), dora.log()[-3000:]


def test_teleop_web_shows_the_camera_and_marks_an_episode_while_it_records(tmp_path):
    """`so101 teleop --record DIR --web` as a person runs it in a terminal: the page shows the camera's
    picture, and the marker from `record` to `stop`."""
    from so101.bodies.task_cameras import IMAGE_SIZE
    from tests.helpers.terminal import start_teleop

    web_port = free_port()
    terminal, _, log_file = start_teleop(tmp_path, "en", extra=f"--record {tmp_path / 'episodes'} --web --web-port {web_port}")
    browser = None
    try:
        address = terminal.wait_for(r"^web view: (http://\S+)$", timeout_s=120).group(1)
        assert address == f"http://127.0.0.1:{web_port}/"
        terminal.seen = terminal.wait_for_prompt(timeout_s=60).start()
        browser = Browser(free_port())
        browser.open(address)
        browser.wait_for_text("shoulder_pan: 0.0°")
        assert "● recording" not in browser.text()
        width, height = IMAGE_SIZE
        camera_pictures = f"Array.from(document.images).filter(i => i.naturalWidth == {width} && i.naturalHeight == {height}).length"
        deadline = time.monotonic() + 60
        while browser.evaluate(camera_pictures) != 1:
            assert time.monotonic() < deadline, "no camera picture on the page"
            time.sleep(0.5)
        terminal.command("record wave twice", re.escape("  ● recording episode 0: task 'wave twice' (stop: stop, drop: discard)"))
        browser.wait_for_text("● recording episode 0: wave twice")
        terminal.command("0 30", r"  → .*")
        time.sleep(1)
        terminal.command("stop", r"  ■ episode 0: \d+ frames .*")
        deadline = time.monotonic() + 30
        while "● recording" in browser.text():
            assert time.monotonic() < deadline, "the marker stayed after stop"
            time.sleep(0.3)
        terminal.command("quit", re.escape("  bye"))
        terminal.wait_for(r"^TELEOP_EXIT=0$", timeout_s=60, after=terminal.seen)
        screen = terminal.screen()
    finally:
        if browser is not None:
            browser.kill()
        terminal.close()
    assert "Traceback" not in screen and "Traceback" not in log_file.read_text(errors="replace"), screen
