"""Where the tip came to rest after `xyz`: a body's servos may stop short of the goal.

IK gives joint goals that put the tip on the target exactly; a body whose servos give way under
the arm's weight (MuJoCo's STS3215 class, a real arm) holds the joints a little off those goals,
and the tip lands millimetres away. `SettleWatch` follows the joint states after the command
until the arm has stopped; the prompt then says where the tip landed if that is more than
LANDED_OFF_MM from the target.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Sequence

# The arm has stopped once no joint moved more than SETTLED_DEG over the last SETTLE_WINDOW_S.
SETTLED_DEG = 0.05
SETTLE_WINDOW_S = 0.5
# An arm still moving this long after the command (held against a limit, swinging undamped)
# is not reported on.
SETTLE_TIMEOUT_S = 30.0
# A landing nearer the target than this is not worth a line.
LANDED_OFF_MM = 2.0


class SettleWatch:
    """The joint states after a command, until the arm has stopped moving.

    `add` takes each state with its time (s, any monotonic clock) and returns the angles the arm
    stopped at, once; None before that and after, and for good once SETTLE_TIMEOUT_S passed.
    """

    def __init__(self, started_s: float):
        self.started_s = started_s
        self.done = False
        self._recent: deque[tuple[float, tuple[float, ...]]] = deque()

    def add(self, time_s: float, joints_deg: Sequence[float]) -> tuple[float, ...] | None:
        if self.done:
            return None
        if time_s - self.started_s > SETTLE_TIMEOUT_S:
            self.done = True
            return None
        angles = tuple(float(angle) for angle in joints_deg)
        self._recent.append((time_s, angles))
        while self._recent and time_s - self._recent[0][0] > SETTLE_WINDOW_S:
            self._recent.popleft()
        # The window must be full: the first states after a command may come before it is applied.
        if time_s - self.started_s < SETTLE_WINDOW_S:
            return None
        spread = max(max(column) - min(column) for column in zip(*(state for _, state in self._recent)))
        if spread > SETTLED_DEG:
            return None
        self.done = True
        return angles


def worth_saying(target_mm: Sequence[float], landed_mm: Sequence[float]) -> bool:
    """Whether a landing is far enough from the target to say so."""
    return math.dist(target_mm, landed_mm) > LANDED_OFF_MM
