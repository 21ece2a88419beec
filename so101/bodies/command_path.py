"""Between the targets sent to a simulated arm and its servos' goals: the command delay, the speed limit
and the calibration of an episode's physics (so101.bodies.physics; fixed physics is its `NOMINAL` point:
no delay, an exact calibration). Both simulated bodies step it each tick, so both see the same goals.
Pure numpy.
"""

from __future__ import annotations

from collections import deque

import numpy as np
import numpy.typing as npt

from so101.bodies.physics import Physics


class CommandPath:
    """Between the targets sent and the servos' goals: `physics`' delay and calibration and, where the body's
    motors cannot cap their own speed (`slews`: MuJoCo's position actuators), its speed limit, by moving the
    goal no faster. PyBullet's motors take the limit as their maxVelocity, as the course's call does."""

    def __init__(self, physics: Physics, goal_deg: npt.ArrayLike, slews: bool):
        self.physics = physics
        self.slews = slews
        self._offsets_deg = np.asarray(physics.calibration_offsets_deg, dtype=np.float64)
        self.goal_deg = self._true(goal_deg)
        self._wanted = self.goal_deg.copy()
        self._queue: deque[tuple[float, npt.NDArray[np.float64]]] = deque()
        self._settled = True

    def _true(self, believed_deg: npt.ArrayLike) -> npt.NDArray[np.float64]:
        # Physics.true_deg's arithmetic, in numpy: the bodies send targets every frame.
        return np.asarray(believed_deg, dtype=np.float64).ravel() - self._offsets_deg

    def send(self, targets_deg: npt.ArrayLike, now_s: float) -> None:
        """Targets as the arm believes them, sent at `now_s`: they reach the servos after the delay."""
        if self.physics.command_delay_s <= 0 and not self._queue:
            self._wanted = self._true(targets_deg)
        else:
            self._queue.append((now_s + self.physics.command_delay_s, self._true(targets_deg)))
        self._settled = False

    @property
    def settled(self) -> bool:
        """Nothing on its way and the goal where it is wanted: ticks until the next send change nothing (a
        flag, not a comparison: the bodies ask it every tick)."""
        return self._settled

    def goal_at(self, now_s: float, tick_s: float) -> npt.NDArray[np.float64]:
        """The servos' goals (true degrees) for the tick starting at `now_s`, `tick_s` long."""
        while self._queue and self._queue[0][0] <= now_s + 1e-9:
            self._wanted = self._queue.popleft()[1]
        if not self.slews:
            self.goal_deg = self._wanted
        else:
            most = self.physics.speed_limit_deg_s * tick_s
            self.goal_deg = self.goal_deg + np.clip(self._wanted - self.goal_deg, -most, most)
        self._settled = not self._queue and (not self.slews or np.array_equal(self.goal_deg, self._wanted))
        return self.goal_deg

    def reported(self, true_deg: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """What the arm reports of joints at `true_deg`."""
        return np.asarray(true_deg, dtype=np.float64) + self._offsets_deg
