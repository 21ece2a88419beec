"""A scripted hand for the emulated arm (`so101 fake-arm` playing a leader): six joint angles at each moment.

Plain functions and one small class, no threads and no clock: so101/feetech/fake_arm.py
(`FakeArm.play_hand`) evaluates a script lazily from time.monotonic(), as it does its motors.
A script maps seconds since the hand started to six angles in degrees, in the order of
so101/robot.py's ACTUATED_JOINTS (shoulder_pan, shoulder_lift, elbow_flex, wrist_flex,
wrist_roll, gripper), in the calibrated arm's degrees: 0° at the middle of each joint's travel,
the gripper from -10° (closed) to 100° (open), as a leader calibrated at its middle pose reads
them (fake_arm.physical_steps puts them on the emulated encoders).

Two scripts: a figure eight (`figure_eight_deg`, endless) and timed keyframes from a text file
(`parse_keyframes`, `load_keyframes`; examples/leader_wave.keyframes is one). A hand starts from
where the joints stand: `eased_in` joins a script from there, so it never jumps.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from so101.robot import ACTUATED_JOINTS

# Seconds since the hand started -> six angles in degrees.
Script = Callable[[float], Sequence[float]]

JOINT_COUNT = len(ACTUATED_JOINTS)
JOINT_NAMES = tuple(joint.name for joint in ACTUATED_JOINTS)

# -- the figure eight ---------------------------------------------------------------------------

# A 1:2 Lissajous figure: shoulder_pan swings once a loop, shoulder_lift and elbow_flex twice, so
# the tip draws a figure eight facing the arm, crossing itself at the home pose's tip (391, 0, 226)
# mm. 30° of pan moves the tip about ±175 mm sideways; 15° of lift with 15° of elbow moves it
# about ±130 mm up and down, its lowest 90 mm above the floor (so101/kinematics.py). Every
# amplitude is under a third of its joint's half-travel (≥ 95°).
SHOULDER_PAN_AMPLITUDE_DEG = 30.0
SHOULDER_LIFT_AMPLITUDE_DEG = 15.0
ELBOW_FLEX_AMPLITUDE_DEG = 15.0
# The wrist gently: it flexes against the arm's tilt (the gripper stays nearer level) and rolls a little.
WRIST_FLEX_AMPLITUDE_DEG = 10.0
WRIST_ROLL_AMPLITUDE_DEG = 10.0
# The gripper opens and closes once a loop, from 5° to 85° (its range is -10° to 100°).
GRIPPER_MIDDLE_DEG = 45.0
GRIPPER_AMPLITUDE_DEG = 40.0
FIGURE_EIGHT_PERIOD_S = 8.0
# How long the hand takes to join the figure eight from where the joints stand.
FIGURE_EIGHT_EASE_S = 1.0


def figure_eight_deg(t_s: float, period_s: float = FIGURE_EIGHT_PERIOD_S) -> tuple[float, ...]:
    """The six angles `t_s` seconds into a figure eight that loops every `period_s`."""
    if not period_s > 0:
        raise ValueError(f"period_s must be positive, got {period_s}")
    phase = 2.0 * math.pi * t_s / period_s
    once, twice = math.sin(phase), math.sin(2.0 * phase)
    return (
        SHOULDER_PAN_AMPLITUDE_DEG * once,
        SHOULDER_LIFT_AMPLITUDE_DEG * twice,
        ELBOW_FLEX_AMPLITUDE_DEG * twice,
        -WRIST_FLEX_AMPLITUDE_DEG * twice,
        WRIST_ROLL_AMPLITUDE_DEG * once,
        GRIPPER_MIDDLE_DEG - GRIPPER_AMPLITUDE_DEG * math.cos(phase),
    )


# -- starting from where the joints stand ----------------------------------------------------------


def smoothstep(fraction: float) -> float:
    """0 at 0, 1 at 1, flat at both ends (clamped outside them): an ease with no jolt."""
    u = min(max(fraction, 0.0), 1.0)
    return u * u * (3.0 - 2.0 * u)


def eased_in(script: Script, start_deg: Sequence[float], ease_s: float) -> Script:
    """`script`, joined from the angles `start_deg`: over its first `ease_s` seconds the hand moves
    from the start into the script (by a smoothstep of the remaining difference), then follows the
    script alone. With ease_s = 0 it is the script from its first instant."""
    if not ease_s >= 0:
        raise ValueError(f"ease_s must be 0 or more, got {ease_s}")
    start = tuple(float(angle) for angle in start_deg)

    def angles_at(t_s: float) -> tuple[float, ...]:
        target = tuple(script(t_s))
        if t_s >= ease_s:
            return target
        weight = smoothstep(t_s / ease_s)
        return tuple(begin + weight * (end - begin) for begin, end in zip(start, target))

    return angles_at


# -- timed keyframes ---------------------------------------------------------------------------------

KEYFRAME_LINE = f"SECONDS then {JOINT_COUNT} angles in degrees ({' '.join(JOINT_NAMES)})"


@dataclass(frozen=True)
class Keyframes:
    """Poses at times: the hand goes in straight lines (in degrees) from one to the next."""

    times_s: tuple[float, ...]  # from 0, strictly increasing
    angles_deg: tuple[tuple[float, ...], ...]  # six per keyframe

    @property
    def duration_s(self) -> float:
        return self.times_s[-1]

    def at(self, t_s: float) -> tuple[float, ...]:
        """The angles at `t_s`: interpolated; the first keyframe before it, the last after the end."""
        after = bisect_right(self.times_s, t_s)
        if after == 0:
            return self.angles_deg[0]
        if after == len(self.times_s):
            return self.angles_deg[-1]
        t0, t1 = self.times_s[after - 1], self.times_s[after]
        fraction = (t_s - t0) / (t1 - t0)
        return tuple(a + fraction * (b - a) for a, b in zip(self.angles_deg[after - 1], self.angles_deg[after]))


def parse_keyframes(text: str, source: str) -> Keyframes:
    """Keyframes from text, one a line: SECONDS and six angles in degrees, separated by spaces;
    blank lines and `#` comments are ignored. ValueError, one line naming `source` and the line,
    for anything else."""
    times: list[float] = []
    poses: list[tuple[float, ...]] = []
    previous_line = 0
    for number, line in enumerate(text.splitlines(), start=1):
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        where = f"{source}, line {number}"
        if len(words) != JOINT_COUNT + 1:
            raise ValueError(f"{where}: {len(words)} value{'s' if len(words) != 1 else ''}; a keyframe is {KEYFRAME_LINE}")
        values = []
        for word in words:
            try:
                value = float(word)
            except ValueError:
                raise ValueError(f"{where}: {word!r} is not a number; a keyframe is {KEYFRAME_LINE}") from None
            if not math.isfinite(value):
                raise ValueError(f"{where}: {word!r} is not a finite number; a keyframe is {KEYFRAME_LINE}")
            values.append(value)
        time_s, angles = values[0], tuple(values[1:])
        if time_s < 0:
            raise ValueError(f"{where}: time {time_s:g} s is negative; times are seconds from the start, 0 or more")
        if times and time_s <= times[-1]:
            raise ValueError(
                f"{where}: time {time_s:g} s does not come after {times[-1]:g} s (line {previous_line}); "
                "each keyframe's time must be later than the one before"
            )
        for joint, angle in zip(ACTUATED_JOINTS, angles):
            if not joint.allows_deg(angle, decimals=1):
                raise ValueError(f"{where}: {joint.name} {angle:g}° is outside its range {joint.limits_text()}")
        times.append(time_s)
        poses.append(angles)
        previous_line = number
    if not times:
        raise ValueError(f"{source}: no keyframes; expected lines of {KEYFRAME_LINE}, # for comments")
    return Keyframes(tuple(times), tuple(poses))


def load_keyframes(path: str | Path) -> Keyframes:
    """parse_keyframes of a file; ValueError, one line, for a file that cannot be read too."""
    path = Path(path).expanduser()
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ValueError(f"no keyframe file {path}") from None
    except UnicodeDecodeError:
        raise ValueError(f"{path} is not a text file of keyframes (not UTF-8)") from None
    except OSError as error:
        raise ValueError(f"cannot read the keyframe file {path}: {error.strerror or error}") from None
    return parse_keyframes(text, str(path))
