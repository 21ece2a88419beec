"""Record and replay as a person does it: `so101 teleop --record` in tmux, two episodes through the
prompt, quit; `so101 replay` of one onto PyBullet and MuJoCo; `so101 dataset` shows both. And
replay onto the emulated real arm: ramped, inside its limits, the tracking error reported."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from so101.dataset.features import ACTION_KEY, STATE_KEY, from_lerobot, to_lerobot
from so101.dataset.reader import Dataset
from so101.dataset.writer import DatasetWriter
from tests.helpers.dataflow import SO101, body_environment
from so101.runtime.cluster import free_port
from so101.runtime.processes import processes_with_env
from tests.helpers.terminal import Terminal, calibrate_in_tmux, send_keys, start_teleop

pytestmark = [pytest.mark.person]

TRACKING_LINE = r"^tracking error \(deg\): p50 (\d+\.\d\d), p99 (\d+\.\d\d), max (\d+\.\d\d)$"
# The last line: the body's joints against the recording's own states, at the same instants.
VERSUS_LINE = r"^versus the recording: p50 (\d+\.\d\d), p99 (\d+\.\d\d) \(deg\)$"


def replay_lines(stdout: str) -> tuple[re.Match, re.Match]:
    """The replay's two last lines, matched: the tracking error, then how the body followed the recording."""
    lines = stdout.strip().splitlines()
    tracking, versus = re.match(TRACKING_LINE, lines[-2]), re.match(VERSUS_LINE, lines[-1])
    assert tracking and versus, stdout
    return tracking, versus


@pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux is not installed (.ci/run installs it)")
def test_a_person_records_two_episodes_quits_and_replays_one_on_both_simulators(tmp_path):
    dataset_dir = tmp_path / "demos"
    terminal, _, log_file = start_teleop(tmp_path, "en", extra=f"--record {dataset_dir}")
    try:
        terminal.seen = terminal.wait_for_prompt(timeout_s=120).start()

        terminal.command("record wave the arm", re.escape("  ● recording episode 0: task 'wave the arm' (stop: stop, drop: discard)"))
        terminal.command("0 40", re.escape("  → joint 0 (shoulder_pan) → 40°"))
        time.sleep(1.5)
        terminal.command("0 -40", re.escape("  → joint 0 (shoulder_pan) → -40°"))
        time.sleep(1.5)
        terminal.command("stop", r"  ■ episode 0: \d+ frames \(\d+\.\d s\), saving\.\.\.")
        terminal.wait_for(r"^  ✓ episode 0 saved: \d+ frames", timeout_s=60, after=terminal.seen)
        terminal.command("record", re.escape("  record format: record TASK TEXT (e.g. 'record put the cube in the box')"))
        terminal.command("record reach forward", re.escape("  ● recording episode 1: task 'reach forward' (stop: stop, drop: discard)"))
        terminal.command("batch 0 30 -30 20 0 60", re.escape("  → all joints → [0.0, 30.0, -30.0, 20.0, 0.0]°, gripper → 60°"))
        time.sleep(2.0)
        terminal.command("stop", r"  ■ episode 1: \d+ frames .*")
        terminal.wait_for(r"^  ✓ episode 1 saved: \d+ frames", timeout_s=60, after=terminal.seen)
        terminal.command("record dropped one", r"  ● recording episode 2: .*")
        terminal.command("discard", r"  episode 2 discarded \(\d+ frames\)")
        # jog's E: an episode of the last task typed (the discarded one's), started and stopped by one key.
        terminal.type_line("jog")
        terminal.seen = terminal.wait_for(r"^  jog mode \(a press moves, holding repeats\):$", timeout_s=20, after=terminal.seen).end()
        send_keys(terminal, "e")
        terminal.wait_for(r"● recording episode 2: task 'dropped one'", timeout_s=20, after=terminal.seen)
        send_keys(terminal, "a", "a")
        time.sleep(1.0)
        send_keys(terminal, "e")
        saved = terminal.wait_for(r"^  ✓ episode 2 saved: \d+ frames.*\n\[joint\] step", timeout_s=60, after=terminal.seen)
        send_keys(terminal, "Escape")
        terminal.seen = terminal.wait_for(r"^  left jog mode$", timeout_s=20, after=saved.start()).end()
        listing = terminal.command("episodes", rf"  {re.escape(str(dataset_dir))}: 3 episodes, 30 fps\n(.*\n.*\n.*)")
        assert "wave the arm" in listing.group(1) and "dropped one" in listing.group(1)
        # The recorder killed mid-episode: the prompt says it does not answer, the episodes stay.
        terminal.command("record doomed", r"  ● recording episode 3: .*")
        time.sleep(1.0)
        (recorder,) = processes_with_env("SO101_RECORD_DIR", str(dataset_dir))
        os.kill(recorder, signal.SIGKILL)
        terminal.command("episodes", re.escape("  the recorder did not answer within 3 s"), timeout_s=30)
        terminal.type_line("quit")
        terminal.wait_for(r"^TELEOP_EXIT=\d+$", timeout_s=60, after=terminal.seen)
    finally:
        terminal.close()

    dataset = Dataset.open(dataset_dir)
    assert [episode.tasks for episode in dataset.episodes] == [("wave the arm",), ("reach forward",), ("dropped one",)]
    assert not list(dataset_dir.rglob("*.so101-new")) and not (dataset_dir / ".so101-work").exists()  # the killed one left nothing
    first = dataset.episode_frames(0)
    actions_deg = from_lerobot(first[ACTION_KEY])
    # What was typed is what was recorded as the action: pan to 40°, then to -40°.
    assert np.isclose(actions_deg[:, 0], 40).any() and np.isclose(actions_deg[-1, 0], -40)
    states_deg = from_lerobot(first[STATE_KEY])
    assert states_deg[:, 0].max() > 35 and states_deg[-1, 0] < -35  # and the arm went there
    second = from_lerobot(dataset.episode_frames(1)[ACTION_KEY])
    assert second[-1] == pytest.approx([0, 30, -30, 20, 0, 60], abs=1e-3)
    pictures = list(dataset.episode_images(0, "observation.images.front"))
    assert len(pictures) == dataset.episodes[0].length and pictures[0].shape == (240, 320, 3)

    summary = subprocess.run([str(SO101), "dataset", str(dataset_dir)], capture_output=True, text=True, timeout=60)
    assert summary.returncode == 0, summary.stderr
    assert "wave the arm" in summary.stdout and "reach forward" in summary.stdout

    for body in ("pybullet", "mujoco"):
        replay = subprocess.run(
            [str(SO101), "replay", str(dataset_dir), "--episode", "0", "--body", body, "--mode", "direct", "--lang", "en",
             "--log", str(tmp_path / f"replay-{body}.log")],
            capture_output=True, text=True, timeout=180)
        assert replay.returncode == 0, replay.stdout + replay.stderr
        match, versus = replay_lines(replay.stdout)
        p50, p99, worst = (float(value) for value in match.groups())
        # The body follows the actions within a few degrees most of the time (half the episode is
        # held at ±40°); the worst is a frame just after a step, no more than the step itself.
        largest_step_deg = float(np.abs(np.diff(actions_deg, axis=0)).max())
        assert p50 < 3.0 and worst <= largest_step_deg + 1.0, (body, replay.stdout, largest_step_deg)
        # ... and where the recording's body was, at the same instants (PyBullet's, recorded at the prompt)
        assert float(versus.group(1)) < 3.0, (body, replay.stdout)


def recorded_episode(dataset_dir: Path, actions_deg: np.ndarray) -> None:
    with DatasetWriter.open(dataset_dir, 30, {}) as writer:
        episode = writer.start_episode("a sweep")
        for action in actions_deg:
            episode.add_frame({STATE_KEY: to_lerobot(action), ACTION_KEY: to_lerobot(action)})
        episode.save()


@pytest.mark.realtime
def test_replay_onto_the_emulated_arm_is_ramped_and_stays_inside_its_limits(tmp_path):
    from so101.feetech.calibration import load_calibration
    from so101.robot import ACTUATED_JOINTS

    # Frame 0 is far from where the arm stands (the ramp's job: 30°/s); then a sweep of shoulder_pan
    # at 22.5°/s that asks for 150°, beyond its 110° limit (the node clamps it).
    frames = 120
    actions = np.zeros((frames, 6))
    actions[:, 1] = 50.0
    actions[:, 0] = np.linspace(60, 150, frames)
    recorded_episode(tmp_path / "set", actions)
    web_port = free_port()
    with body_environment("real", tmp_path) as (env, arm):
        calibration = load_calibration(Path(env["SO101_CALIBRATION"]))
        goals: list[tuple[float, list[int]]] = []
        done = threading.Event()

        def watch() -> None:  # the goal registers, as the bus carries them, each read between two instants
            while not done.is_set():
                asked = time.monotonic()
                goal = [arm.read_register(servo, "Goal_Position") for servo in (1, 2)]
                goals.append((asked, time.monotonic(), goal))
                time.sleep(0.01)

        watcher = threading.Thread(target=watch)
        watcher.start()
        try:
            replay = subprocess.run(
                [str(SO101), "replay", str(tmp_path / "set"), "--body", "real", "--port", env["SO101_PORT"],
                 "--calibration", env["SO101_CALIBRATION"], "--lang", "en", "--log", str(tmp_path / "replay.log"),
                 "--web", "--web-port", str(web_port)], capture_output=True, text=True, timeout=180)
        finally:
            done.set()
            watcher.join()
    assert replay.returncode == 0, replay.stdout + replay.stderr
    replay_lines(replay.stdout)
    pan = calibration["shoulder_pan"]
    pan_goals = [goal[0] for _, _, goal in goals if goal[0]]
    assert pan_goals and min(pan_goals) >= pan.range_min and max(pan_goals) <= pan.range_max
    # Ramped: the goals of the first two joints move at about the ramp's 30°/s, where the arm's own limit
    # in these tests (180°/s) would let a jump through at 180°/s. 4096 steps a turn; speeds over windows
    # of at least 0.3 s, each from the first read's asking to the second's answer (a read answered late
    # stretches the window instead of shortening it). The replay never sends two frames closer than a
    # period (tested with a clock in test_recording.py), but on a loaded machine the body can take its
    # queued commands late, all at once: CI once measured 45°/s of 30 here, a stall of about 0.15 s.
    # Under 60°/s allows a 0.3 s stall and still fails a missing ramp by a factor of three.
    steps_per_deg = 4096 / 360
    windows = [(before, next(after for after in goals[i:] if after[0] - before[0] >= 0.3))
               for i, before in enumerate(goals) if goals[-1][0] - before[0] >= 0.3]
    speeds_deg_s = [abs(after[2][index] - before[2][index]) / steps_per_deg / (after[1] - before[0])
                    for before, after in windows for index in (0, 1)
                    if before[2][index] and after[2][index]]
    assert speeds_deg_s and max(speeds_deg_s) < 60, max(speeds_deg_s)
    assert "moving to the first frame at no more than 30°/s" in replay.stdout
    assert f"web view: http://127.0.0.1:{web_port}/" in replay.stdout.splitlines()  # the replay shown in a browser too
    assert ACTUATED_JOINTS[0].upper_deg < 150


@pytest.mark.realtime
@pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux is not installed (.ci/run installs it)")
def test_a_person_drives_the_simulation_from_the_emulated_leader_records_and_replays(tmp_path):
    """The leader arm's "done when": `so101 fake-arm` as the leader, `so101 calibrate --leader`, then
    `so101 teleop --leader ... --record`; the emulator's figure eight drives the simulation, `state`
    follows it, an episode is recorded and replayed."""
    calibration_file = tmp_path / "leader.json"
    dataset_dir = tmp_path / "leader-demos"
    leader = Terminal(f"{SO101} fake-arm", {"PATH": os.environ["PATH"], "SO101_LANG": "en"})
    terminal = None
    try:
        port = calibrate_in_tmux(leader, calibration_file, "--leader")
        terminal, _, log_file = start_teleop(
            tmp_path, "en", extra=f"--leader {port} --leader-calibration {calibration_file} --record {dataset_dir}")
        terminal.seen = terminal.wait_for_prompt(timeout_s=120).start()
        assert "the leader is ready: move it and the body follows" in terminal.screen()
        leader.type_line("figure8 4")

        def state() -> list[float]:
            reply = terminal.command("state", r"  joint angles now: \[(.*)\]°.*")
            return [float(word) for word in reply.group(1).split(",")]

        time.sleep(1.5)  # the hand eases into the figure eight over its first second
        seen = [state()]
        for _ in range(3):
            time.sleep(0.7)
            seen.append(state())
        pan_deg = [angles[0] for angles in seen]
        assert max(pan_deg) - min(pan_deg) > 5.0, seen  # the simulation follows the hand
        terminal.command("record figure eight", re.escape("  ● recording episode 0: task 'figure eight' (stop: stop, drop: discard)"))
        time.sleep(4.0)
        terminal.command("stop", r"  ■ episode 0: \d+ frames \(\d+\.\d s\), saving\.\.\.")
        terminal.wait_for(r"^  ✓ episode 0 saved: \d+ frames", timeout_s=60, after=terminal.seen)
        leader.type_line("hold")
        terminal.type_line("quit")
        terminal.wait_for(r"^TELEOP_EXIT=0$", timeout_s=60, after=terminal.seen)
        screen = terminal.screen()
    finally:
        if terminal is not None:
            terminal.close()
        leader.close()
    assert "Traceback" not in screen, screen

    actions_deg = from_lerobot(Dataset.open(dataset_dir).episode_frames(0)[ACTION_KEY])
    # The leader drew a figure eight into the episode: its pan swung across tens of degrees.
    assert np.ptp(actions_deg[:, 0]) > 20.0 and np.ptp(actions_deg[:, 1]) > 10.0, actions_deg[:, :2]
    replay = subprocess.run(
        [str(SO101), "replay", str(dataset_dir), "--episode", "0", "--mode", "direct", "--lang", "en",
         "--log", str(tmp_path / "replay.log")], capture_output=True, text=True, timeout=180)
    assert replay.returncode == 0, replay.stdout + replay.stderr
    match, _ = replay_lines(replay.stdout)
    # A hand's smooth motion, not typed steps: the body tracks it within a few degrees throughout.
    p50, p99, worst = (float(value) for value in match.groups())
    assert p50 < 3.0 and worst < 15.0, replay.stdout


@pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux is not installed (.ci/run installs it)")
@pytest.mark.parametrize("body", ["pybullet", "mujoco"])
def test_a_person_records_an_episode_of_the_task_resets_it_and_quits(tmp_path, body):
    from so101.dataset.features import ENVIRONMENT_KEY, SUCCESS_KEY, WRIST_IMAGE_KEY
    from so101.tasks import CUBE_TO_BOX

    dataset_dir = tmp_path / "task-demos"
    terminal, _, log_file = start_teleop(tmp_path, "en", body=body,
                                         extra=f"--task cube_to_box --seed 3 --record {dataset_dir}")
    layout = CUBE_TO_BOX.layout(3)
    try:
        terminal.seen = terminal.wait_for_prompt(timeout_s=120).start()
        terminal.command("task", r"  task cube_to_box, seed 3: cube at \(173, -62\) mm, yaw -12°; box at \(160, 190\) mm\n"
                                 r"  the cube is now at \(173, -62, 12\) mm: not in the box")
        terminal.command("record put the cube in the box", r"  ● recording episode 0: task 'put the cube in the box'.*")
        time.sleep(1.0)  # both cameras' first pictures
        terminal.command("0 40", re.escape("  → joint 0 (shoulder_pan) → 40°"))
        time.sleep(2.0)
        terminal.command("batch -30 30 20 40 0 60", r"  → all joints → .*")
        time.sleep(2.0)
        terminal.command("stop", r"  ■ episode 0: \d+ frames .*")
        terminal.wait_for(r"^  ✓ episode 0 saved: \d+ frames", timeout_s=90, after=terminal.seen)
        terminal.command("reset", r"  → laid out from seed 4, the arm at home: cube at \(122, -137\) mm, yaw -9°; "
                                  r"box at \(160, 190\) mm")
        terminal.command("reset seven", re.escape("  reset format: reset [SEED]") + ".*")
        terminal.type_line("quit")
        terminal.wait_for(r"^TELEOP_EXIT=0$", timeout_s=60, after=terminal.seen)
    finally:
        terminal.close()
    log = log_file.read_text(encoding="utf-8", errors="replace")
    assert "task cube_to_box: laid out from seed 4, the arm at home" in log

    dataset = Dataset.open(dataset_dir)
    frames = dataset.episode_frames(0)
    objects = frames[ENVIRONMENT_KEY]
    assert objects.shape == (dataset.episodes[0].length, 10)
    assert np.allclose(objects[0, 0:3], layout.cube_xyz_m, atol=0.002)  # the cube where seed 3 put it
    assert not frames[SUCCESS_KEY].any()
    states_deg = from_lerobot(frames[STATE_KEY])
    assert states_deg[:, 0].max() > 35  # the arm went to 40°
    for key in ("observation.images.front", WRIST_IMAGE_KEY):
        pictures = np.array([picture.astype(np.int16) for picture in dataset.episode_images(0, key)])
        assert pictures.shape == (dataset.episodes[0].length, 240, 320, 3), key
        changes = np.abs(np.diff(pictures, axis=0)).mean(axis=(1, 2, 3))
        assert (changes > 1.0).sum() >= 2, f"{key}: the pictures did not change while the arm moved"
