"""A recording's servos identified (so101.bodies.servo_fit, `so101 physics --fit`): a known servo recovered,
the ranges file it writes taken by --physics, and the recordings it cannot fit refused in one line."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from so101.bodies.physics import physics_ranges
from so101.bodies.servo_fit import fit_joint, simulate
from so101.dataset.features import ACTION_KEY, STATE_KEY, to_lerobot
from so101.dataset.writer import DatasetWriter
from so101.feetech.fake_arm import FakeArm, Response
from so101.feetech.fake_arm.mechanics import STEPS_PER_DEG
from tests.helpers.dataflow import error_lines, run_so101

FPS = 30
MADE = Path(__file__).parent / "data" / "lerobot_made"


def commands_deg(seed: int, frames: int = 360) -> np.ndarray:
    """A hand's commands: a slow swing with steps in it (the steps reach the speed limit)."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / FPS
    return 30 * np.sin(2 * np.pi * 0.3 * t + rng.uniform(0, 6)) + 15 * np.sign(np.sin(2 * np.pi * 0.1 * t))


def followed(actions: np.ndarray, delay: int, closing: float, speed: float, offset: float, seed: int) -> np.ndarray:
    states = simulate(actions, np.array(actions[0]), delay, np.array([closing]), np.array([speed]), np.array([offset]),
                      FPS)[:, 0]
    return states + np.random.default_rng(seed).normal(0, 0.2, len(states))  # a servo's read noise


class EmulatedServo:
    """`so101 fake-arm`'s shoulder_lift servo on a clock of its own, read and sent goals in degrees from its
    centre."""

    def __init__(self, delay_s: float, time_constant_s: float, speed: float):
        self.now_s = 0.0
        self.arm = FakeArm(ids=(2,), speed_steps_s=speed * STEPS_PER_DEG, clock=lambda: self.now_s,
                           response=Response(delay_s=delay_s, time_constant_s=time_constant_s))
        self.centre = self.arm.read_register(2, "Present_Position")
        self.arm.write_register(2, "Torque_Enable", 1)

    def read_deg(self) -> float:
        return (self.arm.read_register(2, "Present_Position") - self.centre) / STEPS_PER_DEG

    def send_deg(self, goal_deg: float) -> None:
        self.arm.write_register(2, "Goal_Position", round(self.centre + goal_deg * STEPS_PER_DEG))


def emulated(actions: np.ndarray, delay_s: float, time_constant_s: float, speed: float) -> np.ndarray:
    """The servo driven at FPS: each frame its position is read, then the frame's goal is written, as LeRobot's
    follower does."""
    servo = EmulatedServo(delay_s, time_constant_s, speed)
    try:
        states = []
        for frame, action in enumerate(actions):
            servo.now_s = frame / FPS
            states.append(servo.read_deg())
            servo.send_deg(action)
        return np.array(states)
    finally:
        servo.arm.close()


def emulated_through_the_arm_node(actions: np.ndarray, delay_s: float, time_constant_s: float, speed: float,
                                  tick_s: float = 0.02) -> np.ndarray:
    """The same servo behind the real arm's dataflow: its node reads it and writes the newest goal every
    `tick_s` (50 Hz), and the recorder keeps, each frame at FPS, the newest state read."""
    servo = EmulatedServo(delay_s, time_constant_s, speed)
    try:
        states, read = [], 0.0
        for tick in range(int(len(actions) / FPS / tick_s)):
            servo.now_s = tick * tick_s
            while len(states) < len(actions) and len(states) / FPS <= servo.now_s:
                states.append(read)  # the frame's state: the newest read
            read = servo.read_deg()
            servo.send_deg(actions[min(len(actions) - 1, int(servo.now_s * FPS))])
        return np.array(states + [read] * (len(actions) - len(states)))
    finally:
        servo.arm.close()


def steps_and_holds_deg(seed: int, frames: int = 450) -> np.ndarray:
    """A hand that jumps 30-90° at once, from one side to the other, and holds each pose a second: the servo
    turns at its limit."""
    rng = np.random.default_rng(seed)
    poses = np.resize([1.0, -1.0], 20) * rng.uniform(15, 45, 20)
    return np.repeat(poses, 30)[:frames]


def test_the_fit_finds_a_servos_limit_behind_the_arm_nodes_reads():
    """At its limit, a servo read at 50 Hz and recorded at 30 fps seems 25-35% faster than it turns in the
    frames that span two reads: the limit is still found within 15%, and the delay within a frame."""
    episodes = [(actions, emulated_through_the_arm_node(actions, 0.13, 0.05, 60.0))
                for actions in (steps_and_holds_deg(seed) for seed in range(2))]
    fit = fit_joint("shoulder_lift", episodes, FPS)
    assert abs(fit.speed_deg_s / 60.0 - 1) < 0.15 and abs(fit.delay_s - 0.13) <= 1 / FPS, fit
    assert fit.mean_after_deg < 0.2 * fit.mean_before_deg, fit


# A servo whose answer is known: synthetic (delay in frames, closing per frame, deg/s, offset), or the
# emulated arm's (delay, time constant, top speed: closing 1 - exp(-frame / time constant), no offset).
KNOWN = [
    pytest.param(4, 0.3, 120.0, -2.5, lambda actions, seed: followed(actions, 4, 0.3, 120.0, -2.5, seed), id="synthetic"),
    pytest.param(1, 0.6, np.inf, 1.0, lambda actions, seed: followed(actions, 1, 0.6, np.inf, 1.0, seed), id="unlimited"),
    pytest.param(0.13 * FPS, 1 - np.exp(-1 / (FPS * 0.05)), 120.0, 0.0, lambda actions, seed: emulated(actions, 0.13, 0.05, 120.0),
                 id="fake-arm"),
]


@pytest.mark.parametrize("delay, closing, speed, offset, servo", KNOWN)
def test_the_fit_recovers_a_known_servo(delay, closing, speed, offset, servo):
    episodes = [(actions, servo(actions, seed)) for seed, actions in enumerate(commands_deg(seed) for seed in range(3))]
    fit = fit_joint("shoulder_lift", episodes, FPS)
    assert abs(fit.delay_frames - delay) <= 0.5 and abs(fit.closing - closing) < 0.05 * closing + 0.02, fit
    assert abs(fit.offset_deg - offset) < 0.3, fit
    assert (np.isinf(fit.speed_deg_s) if np.isinf(speed) else abs(fit.speed_deg_s / speed - 1) < 0.15), fit
    assert fit.error_after_deg < 0.3 < 2.0 < fit.error_before_deg, fit


def write_recording(root: Path, episodes: int, follow, still_joint: int | None = None) -> None:
    with DatasetWriter.open(root, FPS, {}) as writer:
        for seed in range(episodes):
            actions = np.stack([commands_deg(seed + joint) for joint in range(6)], axis=1)
            actions[:, 5] = 40 + actions[:, 5] / 2  # the gripper within its range
            if still_joint is not None:
                actions[:, still_joint] = 12.0
            states = np.stack([follow(actions[:, joint], seed) for joint in range(6)], axis=1)
            episode = writer.start_episode("a sweep")
            for action, state in zip(actions, states):
                episode.add_frame({ACTION_KEY: to_lerobot(action), STATE_KEY: to_lerobot(state)})
            episode.save()


def test_physics_fit_writes_ranges_centred_on_the_servo_that_physics_files_take(tmp_path):
    recording, ranges_file = tmp_path / "real", tmp_path / "fitted.json"
    # wrist_roll is held still: it tells nothing, and the rest are fitted and scored without it
    write_recording(recording, 3, lambda actions, seed: followed(actions, 4, 0.3, 120.0, -2.0, seed), still_joint=4)
    done = run_so101("physics", "--fit", "--from", str(recording), "-o", str(ranges_file))
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].startswith(f"fit: episodes 0, 1 of {recording} (720 frames at 30 fps); joints in degrees (stated")
    assert re.match(r"  shoulder_pan +4 frames, 133 ms +(9\d) ms +1[12]\d deg/s +-2\.\d\d +9\.\d\d, \d+\.\d\d -> 0\.1\d, 0\.\d\d$",
                    lines[2]), lines[2]
    assert "  not fitted: wrist_roll is commanded across 0.0° only: a fit needs a joint that moves (at least 3°)" in lines
    held_out = re.match(r"held out, episode 2: p50 (\d+\.\d\d) deg before -> (\d+\.\d\d) deg after, mean ", lines[-2])
    assert held_out and float(held_out.group(2)) < 0.3 < 2.0 < float(held_out.group(1)), done.stdout
    ranges = physics_ranges(str(ranges_file))
    assert ranges is not None and ranges.command_delay_s == (0.1, 0.1667)  # 3 to 5 frames at 30 fps
    assert 0.85 * 102 < ranges.speed_limit_deg_s[0] < 0.85 * 138 and ranges.speed_limit_deg_s[1] / ranges.speed_limit_deg_s[0] == pytest.approx(1.15 / 0.85, rel=1e-3)
    low_s, high_s = ranges.servo_time_constant_s  # the synthetic servo's: closing 30% a frame, 93.5 ms
    assert low_s < -1 / (FPS * np.log(0.7)) < high_s and high_s / low_s == pytest.approx(1.25 / 0.75, rel=1e-2)
    assert lines[-1] == (f"wrote {ranges_file}: command_delay_s 0.1-0.1667 (the body's median delay, 4 frames, ± one), "
                         f"servo_time_constant_s {low_s:g}-{high_s:g} (their median, ±25%), speed_limit_deg_s {ranges.speed_limit_deg_s[0]:g}-{ranges.speed_limit_deg_s[1]:g} (the median "
                         f"limit of 4 joints, ±15%); the rest the defaults. Use it: --physics {ranges_file}")


@pytest.mark.parametrize("case, line", [
    ("no state", "so101 physics: {root} has no observation.state: a fit follows the states after the actions"),
    ("still", "so101 physics: no arm joint could be fitted: shoulder_pan is commanded across 0.0° only: a fit needs a "
              "joint that moves (at least 3°)"),
    ("leading", "so101 physics: the fit does not converge: its model follows the recording no better than the commands "
                "do (a mean "),
    ("no fit", "so101 physics: --from goes with --fit"),
])
def test_a_recording_that_cannot_be_fitted_is_refused_in_one_line_and_nothing_is_written(tmp_path, case, line):
    root, ranges_file = tmp_path / "recording", tmp_path / "fitted.json"
    if case == "no state":
        shutil.copytree(MADE, root)
        info = json.loads((root / "meta/info.json").read_text())
        del info["features"][STATE_KEY]
        (root / "meta/info.json").write_text(json.dumps(info))
    elif case == "still":
        with DatasetWriter.open(root, FPS, {}) as writer:
            episode = writer.start_episode("still")
            for _ in range(60):
                episode.add_frame({ACTION_KEY: to_lerobot([10, 20, 30, 0, 0, 50]), STATE_KEY: to_lerobot([10, 20, 30, 0, 0, 50])})
            episode.save()
    elif case == "leading":  # states that come before their actions: no servo does that
        write_recording(root, 2, lambda actions, seed: np.concatenate([actions[5:], np.full(5, actions[-1])]))
    else:
        root.mkdir()
    args = ["physics", "--from", str(root), "-o", str(ranges_file)]
    done = run_so101(*(args if case == "no fit" else ["physics", "--fit", *args[1:]]))
    assert done.returncode == 2 and error_lines(done.stderr) == [error_lines(done.stderr)[0]], done.stderr
    assert error_lines(done.stderr)[0].startswith(line.format(root=root)), done.stderr
    assert not ranges_file.exists()
