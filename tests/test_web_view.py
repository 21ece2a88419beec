"""The web view in a real headless browser (tests/browser.py), every host but 127.0.0.1 unreachable:
the page draws the arm, follows a typed command, its angle text matches joint_state, and a browser
killed mid-stream leaves the dataflow running."""

from __future__ import annotations

import json
import re
import subprocess
import time

import numpy as np
import pytest
from PIL import Image

from tests.browser import CHROMIUM, Browser
from tests.dataflow_helpers import PROMPT_COMMAND, DoraRun, prompt_env, write_test_dataflow

pytestmark = [pytest.mark.dataflow, pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (.ci/run installs it)")]

WEB_PORT = 8131
DEBUG_PORT = 9341
# The page's right-hand panel (angles, plot) starts about here at 1200 px wide; the arm is drawn left of it.
PANEL_LEFT_PX = 860
# The arm drawn: this many pixels of the URDF's 3d_printed yellow, lit or shaded.
ARM_PIXELS = 3000


def angle_on_page(text: str, joint: str) -> float:
    match = re.search(rf"^{joint}: (-?\d+\.\d)°$", text, re.MULTILINE)
    assert match, text[:500]
    return float(match.group(1))


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


def test_the_page_draws_the_arm_follows_0_90_and_outlives_its_browser(tmp_path):
    record_file = tmp_path / "joint_state.json"
    dataflow = write_test_dataflow(tmp_path, {"SO101_LANG": "en"}, record_file=record_file,
                                   web_env={"SO101_WEB_PORT": str(WEB_PORT)})
    dora = DoraRun(dataflow, tmp_path / "dora.log", stop_after_s=300)
    browser = prompt = None
    try:
        dora.wait_for(f"web view: http://127.0.0.1:{WEB_PORT}/", timeout_s=60)
        browser = Browser(DEBUG_PORT)
        browser.open(f"http://127.0.0.1:{WEB_PORT}/")
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
        text = browser.wait_for_text("shoulder_pan: 9")
        time.sleep(2)  # settled
        text = browser.text()
        after = the_arm_drawn(browser, tmp_path / "after.png")
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
    assert angle_on_page(text, "shoulder_pan") == pytest.approx(90.0, abs=0.5)
    # The browser killed: states go on, and the web view did not fail.
    assert any(t > killed_at + 1.5 for t, _ in samples)
    assert "Traceback" not in log and "web_view: daemon exited with code" not in log, log[-3000:]
