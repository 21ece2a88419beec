"""A hand moving torque-off joints: a calibration's sweep to both stops, or a script of angles
(so101/feetech/hand.py's figure eight, keyframes) played as a leader arm. Both are paths in time,
evaluated lazily from the emulator's clock as its motors are."""

from __future__ import annotations

import math
from typing import Callable, Sequence

from so101.feetech import sts3215
from so101.feetech.fake_arm.mechanics import MIDDLE, Mechanics, script_steps

# `sweep`: how long the hand rests on each stop, as a share of the whole sweep.
SWEEP_DWELL_SHARE = 0.1
# A scripted hand's Present_Velocity: the change of position over this much time either side.
VELOCITY_SPAN_S = 0.001


class HandPath:
    """A hand moving a joint: straight lines between (time, unwrapped physical position) points."""

    def __init__(self, points: list[tuple[float, float]]):
        self.points = points

    @property
    def end_time(self) -> float:
        return self.points[-1][0]

    def at(self, now: float) -> tuple[float, float]:
        """(position, velocity in steps/s) at `now`."""
        if now >= self.end_time:
            return self.points[-1][1], 0.0
        if now <= self.points[0][0]:
            return self.points[0][1], 0.0
        for (t0, p0), (t1, p1) in zip(self.points, self.points[1:]):
            if now < t1:
                slope = (p1 - p0) / (t1 - t0) if t1 > t0 else 0.0
                return p0 + slope * (now - t0), slope
        return self.points[-1][1], 0.0


def sweep_path(mechanics: Mechanics, start: float, now: float, duration_s: float) -> HandPath:
    """A person calibrating, from physical position `start` at `now`: to one stop, a rest there, to
    the other stop, a rest, back to the middle, in `duration_s`. A joint without stops (wrist_roll)
    turns half a turn each way from its middle (a full turn)."""
    m = mechanics
    if m.stops is not None:
        lower, upper = (float(stop) for stop in m.stops)
    else:  # unwrap around the middle: the hand turns it 180° each way
        turn = sts3215.STEPS_PER_TURN
        start = m.centre + ((start - m.centre + MIDDLE) % turn - MIDDLE)
        lower, upper = float(m.centre - MIDDLE), float(m.centre + MIDDLE)
    dwell = SWEEP_DWELL_SHARE * duration_s
    legs = (abs(lower - start), upper - lower, abs(upper - m.centre))
    moving = duration_s - 2 * dwell
    per_step = moving / sum(legs)
    t = now
    points = [(t, start)]
    t += legs[0] * per_step
    points.append((t, lower))
    t += dwell
    points.append((t, lower))
    t += legs[1] * per_step
    points.append((t, upper))
    t += dwell
    points.append((t, upper))
    points.append((now + duration_s, float(m.centre)))
    return HandPath(points)


class ScriptedHand:
    """A hand moving one joint along a script of six angles in degrees (FakeArm.play_hand),
    from `start` (the emulator's clock) for `duration_s` (None: until it is stopped)."""

    def __init__(self, script: Callable[[float], Sequence[float]], mechanics: Mechanics, start: float,
                 duration_s: float | None):
        self.script = script
        self.mechanics = mechanics
        self.index = mechanics.servo_id - 1
        self.start = start
        self.duration_s = duration_s

    @property
    def end_time(self) -> float:
        return math.inf if self.duration_s is None else self.start + self.duration_s

    def _steps(self, t_s: float) -> float:
        return script_steps(self.mechanics, float(self.script(t_s)[self.index]))

    def at(self, now: float) -> tuple[float, float]:
        """(position, velocity in steps/s) at `now`; the velocity by a central difference."""
        t_s = max(0.0, now - self.start)
        if self.duration_s is not None and t_s >= self.duration_s:
            return self._steps(self.duration_s), 0.0
        before = max(0.0, t_s - VELOCITY_SPAN_S)
        after = t_s + VELOCITY_SPAN_S
        if self.duration_s is not None:
            after = min(after, self.duration_s)
        return self._steps(t_s), (self._steps(after) - self._steps(before)) / (after - before)
