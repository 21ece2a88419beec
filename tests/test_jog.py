"""Key jogging without a terminal or dora: what each key does (so101/prompt/jog.py), and the raw key
reader on a pseudo-terminal, restored however it ends (so101/prompt/terminal.py)."""

from __future__ import annotations

import os
import signal
import termios
import threading
import time

import pytest
from hypothesis import given, strategies as st

from so101.prompt.jog import JOINT_KEYS, MAX_IK_SWING_DEG, STEPS_DEG, Jog, press, status_line
from so101.robot import ACTUATED_JOINTS
from so101.prompt.terminal import KeyReader, single_keys

HOME6 = (0.0, 0.0, 0.0, 0.0, 0.0, 45.0)


class StraightLineArm:
    """A stand-in for so101.kinematics.Kinematics: the tip is the first three angles, in mm."""

    def __init__(self, reachable=True, swing=0.0):
        self.reachable, self.swing = reachable, swing

    def tip_mm(self, arm_deg):
        return tuple(arm_deg[:3])

    def solve(self, target_mm, seed_deg=None):
        from so101.kinematics import Reach

        joints = tuple(target_mm) + (seed_deg[3] + self.swing, seed_deg[4])
        return Reach(joints, tuple(target_mm), 0.0 if self.reachable else 50.0)


def test_w_raises_the_arm_and_s_lowers_it_by_one_step():
    jog = Jog(HOME6)
    pressed = press(jog, "w", HOME6, None)
    assert pressed.send_deg == (0.0, -2.0, 0.0, 0.0, 0.0, 45.0)  # a negative shoulder_lift raises the arm
    pressed = press(pressed.jog, "W", HOME6, None)  # caps lock: the same key
    assert pressed.send_deg[1] == -4.0
    assert press(pressed.jog, "s", HOME6, None).send_deg[1] == -2.0


@pytest.mark.parametrize("key, joint, direction", [(key, *value) for key, value in JOINT_KEYS.items()])
def test_every_joint_key_moves_its_joint_by_the_step(key, joint, direction):
    pressed = press(Jog(HOME6, step_index=3), key, HOME6, None)
    expected = list(HOME6)
    expected[joint] += direction * STEPS_DEG[3]
    assert pressed.send_deg == tuple(expected)


def test_holding_a_key_stops_at_the_limit_and_says_so():
    jog = Jog(HOME6, step_index=4)  # 10° a press
    sent = []
    for _ in range(20):  # a held key: repeated presses
        pressed = press(jog, "w", HOME6, None, lang="en")
        jog = pressed.jog
        if pressed.send_deg:
            sent.append(pressed.send_deg[1])
    lower = ACTUATED_JOINTS[1].lower_deg
    # -10° ... -100°, then the last hair to the URDF's -1.74533 rad (-100.00004°): then nothing more to send.
    assert sent == [-10.0 * n for n in range(1, 11)] + [lower]
    assert jog.note == f"shoulder_lift at its limit {lower:.1f}°"
    assert "| shoulder_lift at its limit -100.0°" in status_line(jog, HOME6, None, "en")


@given(keys=st.lists(st.sampled_from(list(JOINT_KEYS) + ["-", "+", "h", "space", "?", "é", "up"]), max_size=60))
def test_no_key_sequence_leaves_the_limits(keys):
    jog = Jog(HOME6)
    for key in keys:
        pressed = press(jog, key, HOME6, None)
        jog = pressed.jog
        for angle, joint in zip(pressed.send_deg or jog.targets_deg, ACTUATED_JOINTS):
            assert joint.lower_deg <= angle <= joint.upper_deg


def test_step_keys_home_hold_map_and_leave():
    jog = Jog((10.0, -20.0, 5.0, 0.0, 0.0, 30.0))
    assert press(jog, "-", None, None).jog.step_deg == 1.0
    assert press(jog, "+", None, None).jog.step_deg == 5.0
    assert press(Jog(HOME6, step_index=0), "-", None, None).jog.step_index == 0  # no finer than the finest
    assert press(jog, "h", None, None).send_deg == (0.0, 0.0, 0.0, 0.0, 0.0, 30.0)  # the gripper stays
    assert press(jog, "space", (1.0, 2.0, 3.0, 4.0, 5.0, 6.0), None).send_deg == (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
    assert press(jog, "m", None, None).show_map and press(jog, "?", None, None).show_map
    assert press(jog, "esc", None, None).leave and press(jog, "q", None, None).leave
    unknown = press(jog, "p", None, None, lang="en")
    assert unknown.send_deg is None and unknown.jog.note == "key 'p' does nothing (M shows the keys)"


def test_cartesian_keys_move_the_tip_along_the_base_axes():
    arm = StraightLineArm()
    jog = press(Jog((100.0, 0.0, 50.0, 0.0, 0.0, 45.0)), "tab", None, arm).jog
    assert jog.cartesian and jog.step_mm == 5.0
    assert press(jog, "w", None, arm).send_deg[:3] == (100.0, 0.0, 55.0)  # up
    assert press(jog, "a", None, arm).send_deg[:3] == (100.0, 5.0, 50.0)  # left is +y
    assert press(jog, "f", None, arm).send_deg[:3] == (95.0, 0.0, 50.0)  # back
    assert press(jog, "t", None, arm).send_deg[3] == -2.0  # keys without a Cartesian meaning still move joints, by the step in degrees


def test_cartesian_steps_out_of_reach_or_with_a_swing_send_nothing():
    jog = Jog(HOME6, cartesian=True)
    far = press(jog, "r", None, StraightLineArm(reachable=False), lang="en")
    assert far.send_deg is None and far.jog.note == "out of reach: (5, 0, 0) mm"
    swing = press(jog, "r", None, StraightLineArm(swing=MAX_IK_SWING_DEG + 5), lang="en")
    assert swing.send_deg is None and swing.jog.note == "that step needs wrist_flex to swing 25°: not sent"


def test_without_kinematics_tab_says_why():
    pressed = press(Jog(HOME6), "tab", None, FileNotFoundError("model missing"), lang="en")
    assert not pressed.jog.cartesian
    assert pressed.jog.note == "Cartesian mode is not available: model missing"


# -- the terminal ---------------------------------------------------------------------------


@pytest.fixture
def pty():
    leader, follower = os.openpty()
    yield leader, follower
    os.close(leader)
    os.close(follower)


def test_keys_are_read_one_by_one_with_names(pty):
    leader, follower = pty
    with single_keys(follower) as reader:
        assert isinstance(reader, KeyReader)
        os.write(leader, b"wW \t\x1b[A\x1b[1;5C\xe4\xbd\xa0q")
        keys = [reader.read(0.2) for _ in range(9)]
        os.write(leader, b"\x1b")
        escape = reader.read(0.2)
    assert keys == ["w", "W", "space", "tab", "up", "right", "你", "q", None]  # Ctrl+Right reads as right
    assert escape == "esc"  # Esc alone, after the wait for a sequence


@pytest.mark.parametrize("ending", ["normal", "exception", "Ctrl-C", "SIGTERM", "SIGHUP"])
def test_the_terminal_is_restored_however_jogging_ends(pty, ending):
    _, follower = pty
    before = termios.tcgetattr(follower)
    handlers_before = [signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGHUP)]
    raised = {"exception": ValueError, "Ctrl-C": KeyboardInterrupt, "SIGTERM": KeyboardInterrupt,
              "SIGHUP": KeyboardInterrupt}.get(ending)
    with pytest.raises(raised) if raised else _nothing():
        with single_keys(follower):
            during = termios.tcgetattr(follower)
            assert not during[3] & termios.ICANON and not during[3] & termios.ECHO
            assert during[3] & termios.ISIG  # Ctrl-C still interrupts
            if ending == "exception":
                raise ValueError("a bug")
            if ending == "Ctrl-C":
                raise KeyboardInterrupt
            if ending in ("SIGTERM", "SIGHUP"):
                signum = getattr(signal, ending)
                threading.Timer(0.05, os.kill, (os.getpid(), signum)).start()
                time.sleep(2)
    assert termios.tcgetattr(follower) == before
    assert [signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGHUP)] == handlers_before


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False
