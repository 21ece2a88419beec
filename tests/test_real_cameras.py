"""The real arm's eyes as a person uses them, without hardware: `so101 fake-arm`'s emulated bus and video
files that carry their frame numbers as the cameras, `so101 teleop --body real --camera ... --record` typed
in tmux. The recorded front frames are the file's, in order, each paired with the state of its moment; a
camera that vanishes mid-episode is said in one line and the episode's part so far is kept; the arm stays
driven, and its torque goes off at the end."""

from __future__ import annotations

import re
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from so101.dataset.reader import Dataset
from so101.dataset.features import IMAGE_KEY, STATE_KEY, WRIST_IMAGE_KEY
from tests.helpers.dataflow import body_environment
from tests.helpers.numbered_video import video_frame_numbers, write_numbered_video
from tests.helpers.terminal import start_teleop

pytestmark = [pytest.mark.person, pytest.mark.realtime,
              pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux is not installed (.ci/run installs it)")]

STATE = r"  joint angles now: \[(-?[\d.]+), .*"


def teleop_on_the_emulated_arm(tmp_path: Path, env: dict[str, str], cameras: str):
    """`so101 teleop --body real` on the emulated arm with `cameras` (its --camera options), recording into
    tmp_path/real, in a new terminal whose prompt is ready; returns it and the dataflow's log."""
    terminal, _, log_file = start_teleop(
        tmp_path, "en", body="real",
        extra=f"--port {env['SO101_PORT']} --calibration {env['SO101_CALIBRATION']} {cameras} --record {tmp_path / 'real'}")
    terminal.seen = terminal.wait_for_prompt(timeout_s=120).start()
    return terminal, log_file


def quit_cleanly(terminal) -> None:
    """`quit` at the prompt: the session ends with exit code 0 and no traceback."""
    terminal.type_line("quit")
    terminal.wait_for(r"^TELEOP_EXIT=0$", timeout_s=60, after=terminal.seen)
    assert "Traceback" not in terminal.screen(), terminal.screen()


def torque_is_off(arm) -> bool:
    return [arm.read_register(servo, "Torque_Enable") for servo in range(1, 7)] == [0] * 6


def front_video(dataset_dir: Path) -> Path:
    return next((dataset_dir / "videos" / IMAGE_KEY).rglob("*.mp4"))


def test_file_cameras_on_the_emulated_arm_record_the_files_frames_in_order_paired_with_their_states(tmp_path):
    front = write_numbered_video(tmp_path / "front.mp4", 1000)
    wrist = write_numbered_video(tmp_path / "wrist.mp4", 1000, width=320, height=240)
    dataset_dir = tmp_path / "real"
    with body_environment("real", tmp_path) as (env, arm):
        terminal, log_file = teleop_on_the_emulated_arm(tmp_path, env, f"--camera front={front} --camera wrist={wrist}")
        try:
            terminal.command("record look at the arm", r"  ● recording episode 0: task 'look at the arm' .*")
            terminal.command("0 30", re.escape("  → joint 0 (shoulder_pan) → 30°"))
            time.sleep(2.0)
            terminal.command("0 -20", re.escape("  → joint 0 (shoulder_pan) → -20°"))
            time.sleep(2.0)
            terminal.command("stop", r"  ■ episode 0: \d+ frames \(\d+\.\d s\), saving\.\.\.")
            terminal.wait_for(r"^  ✓ episode 0 saved: \d+ frames", timeout_s=60, after=terminal.seen)
            quit_cleanly(terminal)
        finally:
            terminal.close()
        assert torque_is_off(arm)  # on the way out
    dataset = Dataset.open(dataset_dir)
    frames = dataset.episode_frames(0)
    assert {IMAGE_KEY, WRIST_IMAGE_KEY} <= set(dataset.info["features"]), dataset.info["features"]
    assert dataset.info["features"][IMAGE_KEY]["shape"][:2] == [480, 640]
    pan = np.asarray(frames[STATE_KEY])[:, 0]
    assert pan.max() > 25 and pan.min() < -15  # the arm moved while it was recorded
    numbers = video_frame_numbers(front_video(dataset_dir))
    steps = np.diff(numbers)
    # The file's frames in order: each frame the next one or the same, at most one missed in a row at 30 fps.
    assert len(numbers) == len(pan) and steps.min() >= 0 and steps.max() <= 2, numbers
    assert np.mean(steps == 1) > 0.8, numbers
    log = log_file.read_text()
    paired = re.search(r"episode 0: each picture paired with the state sent nearest its capture, at most (\d+) ms apart",
                       log)
    assert paired and int(paired.group(1)) <= 33, log[-3000:]  # within one frame's time at 30 fps


def test_a_camera_that_vanishes_mid_episode_is_said_and_the_episode_so_far_is_kept(tmp_path):
    front = write_numbered_video(tmp_path / "front.mp4", 1000, width=320, height=240)
    kept = tmp_path / "front-kept.mp4"
    shutil.copy(front, kept)
    dataset_dir = tmp_path / "real"
    with body_environment("real", tmp_path) as (env, arm):
        terminal, log_file = teleop_on_the_emulated_arm(tmp_path, env, f"--camera front={front} --camera-size 320x240")
        try:
            terminal.command("record until it vanishes", r"  ● recording episode 0: .*")
            time.sleep(2.0)
            front.write_bytes(b"")  # the camera vanishes: its reads fail, and it cannot be opened again
            lost = terminal.wait_for(r"^  ✗ the front camera sent no picture for \d\.\d s: ■ episode 0: (\d+) frames "
                                     r"\(\d+\.\d s\), saving\.\.\.$", timeout_s=20, after=terminal.seen)
            terminal.wait_for(r"^  ✓ episode 0 saved: \d+ frames", timeout_s=60, after=terminal.seen)
            # The arm is still driven as before.
            terminal.command("0 40", re.escape("  → joint 0 (shoulder_pan) → 40°"))
            time.sleep(1.5)
            assert abs(float(terminal.command("state", STATE).group(1)) - 40.0) < 2.0
            terminal.command("record again", r"  the front camera has sent no picture for \d+\.\d s: not recording "
                                             r"\(is it plugged in\?\)")
            shutil.copy(kept, front)  # plugged in again
            deadline = time.monotonic() + 20
            while "is back" not in log_file.read_text() and time.monotonic() < deadline:
                time.sleep(0.2)
            quit_cleanly(terminal)
        finally:
            terminal.close()
        assert torque_is_off(arm)  # on the way out
    log = log_file.read_text()
    assert re.search(rf"camera front: {re.escape(str(front))} stopped \(no picture came", log), log[-3000:]
    assert f"camera front: {front} is back" in log, log[-3000:]
    frames = Dataset.open(dataset_dir).episode_frames(0)
    assert len(frames[STATE_KEY]) == int(lost.group(1)) > 30  # the part before it vanished, all of it
