"""The scripted hand (so101/feetech/hand.py): the figure eight and timed keyframes, worked out by hand."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from so101.feetech.hand import (
    FIGURE_EIGHT_PERIOD_S,
    Keyframes,
    eased_in,
    figure_eight_deg,
    load_keyframes,
    parse_keyframes,
    smoothstep,
)
from so101.robot import ACTUATED_JOINTS

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "leader_wave.keyframes"
R = math.sqrt(0.5)  # sin 45°

# -- the figure eight -------------------------------------------------------------------------


@pytest.mark.parametrize("t_s, expected", [
    # pan 30 sin(wt); lift and elbow 15 sin(2wt); wrist_flex -10 sin(2wt); roll 10 sin(wt); gripper 45 - 40 cos(wt)
    (0.0, (0.0, 0.0, 0.0, 0.0, 0.0, 5.0)),
    (1.0, (30 * R, 15.0, 15.0, -10.0, 10 * R, 45 - 40 * R)),  # an eighth of the 8 s loop: wt = 45°
    (2.0, (30.0, 0.0, 0.0, 0.0, 10.0, 45.0)),
    (3.0, (30 * R, -15.0, -15.0, 10.0, 10 * R, 45 + 40 * R)),
    (4.0, (0.0, 0.0, 0.0, 0.0, 0.0, 85.0)),
    (6.0, (-30.0, 0.0, 0.0, 0.0, -10.0, 45.0)),
    (8.0, (0.0, 0.0, 0.0, 0.0, 0.0, 5.0)),
])
def test_the_figure_eight_at_hand_computed_times(t_s, expected):
    assert figure_eight_deg(t_s) == pytest.approx(expected, abs=1e-9)


def test_a_shorter_period_is_the_same_loop_faster():
    assert figure_eight_deg(0.5, period_s=2.0) == pytest.approx(figure_eight_deg(2.0), abs=1e-9)
    with pytest.raises(ValueError, match="period_s must be positive"):
        figure_eight_deg(1.0, period_s=0.0)


def test_the_figure_eight_stays_well_inside_every_joints_travel():
    samples = [figure_eight_deg(i * FIGURE_EIGHT_PERIOD_S / 400) for i in range(400)]
    for index, joint in enumerate(ACTUATED_JOINTS):
        angles = [pose[index] for pose in samples]
        if joint.name == "gripper":
            assert (min(angles), max(angles)) == pytest.approx((5.0, 85.0), abs=0.01)
            continue
        half_travel = (joint.upper_deg - joint.lower_deg) / 2
        assert max(abs(angle) for angle in angles) <= half_travel / 3, joint.name


def test_the_tip_draws_a_figure_eight_above_the_floor():
    from so101.kinematics import Kinematics

    with Kinematics() as kinematics:
        def tip(t_s):
            return kinematics.tip_mm(figure_eight_deg(t_s)[:5])

        home = tip(0.0)
        assert tip(4.0) == pytest.approx(home, abs=0.01)  # it crosses itself at the home pose's tip
        # The right lobe (y < 0: positive pan turns the arm to its right) below, then above home ...
        right_low, right_high = tip(1.0), tip(3.0)
        assert right_low[1] < -100 and right_high[1] < -100
        assert right_low[2] < home[2] - 100 and right_high[2] > home[2] + 100
        # ... and the left one, its mirror image.
        assert tip(5.0) == pytest.approx((right_low[0], -right_low[1], right_low[2]), abs=0.5)
        assert tip(7.0) == pytest.approx((right_high[0], -right_high[1], right_high[2]), abs=0.5)
        assert min(tip(i / 10)[2] for i in range(80)) > 80  # mm above the floor


# -- starting from where the joints stand ------------------------------------------------------------


def test_smoothstep():
    assert [smoothstep(u) for u in (-1.0, 0.0, 0.25, 0.5, 1.0, 2.0)] == [0.0, 0.0, 0.15625, 0.5, 1.0, 1.0]


def test_eased_in_goes_from_the_start_into_the_script():
    script = eased_in(lambda t_s: (10.0 + t_s,) * 6, start_deg=(-20.0,) * 6, ease_s=2.0)
    assert script(0.0) == pytest.approx((-20.0,) * 6)  # exactly where the joints stood
    # At 0.5 s (a quarter): -20 + 0.15625 x (10.5 - -20) = -15.234375.
    assert script(0.5) == pytest.approx((-15.234375,) * 6)
    assert script(1.0) == pytest.approx((-4.5,) * 6)  # half way: -20 + 0.5 x (11 - -20)
    assert script(2.0) == pytest.approx((12.0,) * 6)  # the script alone from then on
    assert script(5.0) == pytest.approx((15.0,) * 6)
    assert eased_in(lambda t_s: (3.0,) * 6, (0.0,) * 6, ease_s=0.0)(0.0) == (3.0,) * 6  # no ease: at once


def test_the_eased_figure_eight_never_jumps():
    start = (50.0, -40.0, 60.0, -30.0, 170.0, 100.0)  # far from the figure eight
    script = eased_in(figure_eight_deg, start, ease_s=1.0)
    poses = [script(i * 0.001) for i in range(3000)]
    assert poses[0] == pytest.approx(start)
    for a, b in zip(poses, poses[1:]):
        # At most 0.5° a millisecond (the figure eight alone: pan 30° x 2π/8 s ≈ 0.024°/ms).
        assert max(abs(x - y) for x, y in zip(a, b)) < 0.5


# -- timed keyframes ------------------------------------------------------------------------------------


WAVE = """\
# a comment line, then a blank one

0.5   10 0 0 0 0 50     # comment after a keyframe
1.5  -10 20 -30 40 -50 100
2     0 0 0 0 0 -10
"""


def test_keyframes_parse_and_interpolate_in_straight_lines():
    keyframes = parse_keyframes(WAVE, "wave")
    assert keyframes.times_s == (0.5, 1.5, 2.0)
    assert keyframes.duration_s == 2.0
    assert keyframes.at(0.0) == (10, 0, 0, 0, 0, 50)  # before the first: the first
    assert keyframes.at(0.5) == (10, 0, 0, 0, 0, 50)
    assert keyframes.at(0.75) == pytest.approx((5.0, 5.0, -7.5, 10.0, -12.5, 62.5))  # a quarter of the way
    assert keyframes.at(1.75) == pytest.approx((-5.0, 10.0, -15.0, 20.0, -25.0, 45.0))  # half of the last leg
    assert keyframes.at(2.0) == (0, 0, 0, 0, 0, -10)
    assert keyframes.at(60.0) == (0, 0, 0, 0, 0, -10)  # held after the end


def test_a_single_keyframe_at_zero():
    keyframes = parse_keyframes("0 1 2 3 4 5 6", "one")
    assert keyframes == Keyframes((0.0,), ((1.0, 2.0, 3.0, 4.0, 5.0, 6.0),))
    assert keyframes.duration_s == 0.0 and keyframes.at(3.0) == (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)


def test_keyframes_reached_from_where_the_joints_stand_by_the_first_keyframes_time():
    keyframes = parse_keyframes(WAVE, "wave")
    script = eased_in(keyframes.at, (0.0,) * 6, ease_s=keyframes.times_s[0])
    assert script(0.0) == (0.0,) * 6
    assert script(0.25) == pytest.approx((5.0, 0, 0, 0, 0, 25.0))  # half the time, half the way
    assert script(0.5) == keyframes.at(0.5)
    assert script(1.0) == keyframes.at(1.0)


NAMES = "shoulder_pan shoulder_lift elbow_flex wrist_flex wrist_roll gripper"
LINE = f"a keyframe is SECONDS then 6 angles in degrees ({NAMES})"


@pytest.mark.parametrize("text, message", [
    ("0 1 2 3 4 5\n", f"moves.txt, line 1: 6 values; {LINE}"),
    ("# header\n\n0 1 2 3 4 5 6 7\n", f"moves.txt, line 3: 8 values; {LINE}"),
    ("0 0 0 0 0 0 0\n1 0 0 ten 0 0 0\n", f"moves.txt, line 2: 'ten' is not a number; {LINE}"),
    ("0 0 0 0 nan 0 0\n", f"moves.txt, line 1: 'nan' is not a finite number; {LINE}"),
    ("1 0 0 0 0 0 inf\n", f"moves.txt, line 1: 'inf' is not a finite number; {LINE}"),
    ("-1 0 0 0 0 0 0\n", "moves.txt, line 1: time -1 s is negative; times are seconds from the start, 0 or more"),
    ("1 0 0 0 0 0 0\n\n# again\n1 0 0 0 0 0 0\n",
     "moves.txt, line 4: time 1 s does not come after 1 s (line 1); each keyframe's time must be later than the one before"),
    ("2 0 0 0 0 0 0\n1.5 0 0 0 0 0 0\n",
     "moves.txt, line 2: time 1.5 s does not come after 2 s (line 1); each keyframe's time must be later than the one before"),
    ("0 120 0 0 0 0 0\n", "moves.txt, line 1: shoulder_pan 120° is outside its range [-110.0°, 110.0°]"),
    ("0 0 0 0 0 0 -20\n", "moves.txt, line 1: gripper -20° is outside its range [-10.0°, 100.0°]"),
    ("", f"moves.txt: no keyframes; expected lines of SECONDS then 6 angles in degrees ({NAMES}), # for comments"),
    ("# only a comment\n\n", f"moves.txt: no keyframes; expected lines of SECONDS then 6 angles in degrees ({NAMES}), # for comments"),
])
def test_a_bad_keyframe_is_one_line_naming_the_file_and_the_line(text, message):
    with pytest.raises(ValueError) as raised:
        parse_keyframes(text, "moves.txt")
    assert str(raised.value) == message


def test_the_limits_are_as_shown_to_one_place():
    keyframes = parse_keyframes("0 110 -100 0 0 0 100\n", "edge")  # shoulder_pan's limit is 110.0002°
    assert keyframes.at(0.0) == (110.0, -100.0, 0.0, 0.0, 0.0, 100.0)


def test_load_keyframes_reads_a_file_or_says_why_not_in_one_line(tmp_path):
    assert load_keyframes(str(EXAMPLE)).duration_s == 6.0
    with pytest.raises(ValueError, match=r"^no keyframe file .*nowhere\.keyframes$"):
        load_keyframes(tmp_path / "nowhere.keyframes")
    binary = tmp_path / "binary.keyframes"
    binary.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(ValueError, match=r"binary\.keyframes is not a text file of keyframes \(not UTF-8\)$"):
        load_keyframes(binary)
    with pytest.raises(ValueError, match=r"^cannot read the keyframe file .*: Is a directory$"):
        load_keyframes(tmp_path)


def test_the_example_wave_raises_the_forearm_waves_three_times_and_comes_back():
    keyframes = load_keyframes(EXAMPLE)
    assert keyframes.times_s[0] > 0  # reached from wherever the joints stand, no jump
    assert keyframes.at(1.0) == (0, -10, -80, 0, 0, 20)
    wrist = [pose[3] for pose in keyframes.angles_deg]
    assert wrist.count(30) == 3 and wrist.count(-30) == 2
    assert keyframes.at(keyframes.duration_s) == (0, 0, 0, 0, 0, 45)  # the middle pose
    assert keyframes.duration_s == 6.0
