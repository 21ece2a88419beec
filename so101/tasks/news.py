"""What a person is told of the cube and the box: one line when it comes to rest in the box, one when it is taken away.

The success function (cube_to_box.CubeToBox.succeeded) judges one instant: an episode ends at its
first frame at rest in the box. Instant by instant it flickers while the cube settles: at seed 12 the
expert's jaws opening and the arm leaving jolt the cube faster than REST_SPEED_M_S eight times in a
tenth of a second, while it moves 1.2 mm. News follows what a person sees instead: the cube is in the
box from the first instant the success function says so until it has been moved more than
`MOVED_M` from where it last lay there at rest. Pure: it is given each judgement and object_state,
and says which news, if any, they make.
"""

from __future__ import annotations

import math
from typing import Sequence

# The names of the news, as the prompt's texts are keyed.
LANDED = "landed_in_box"
LEFT = "left_box"

# A cube moved farther than this from where it lay at rest in the box was taken from there: far above
# the millimetre a release jolts it by, below a push a person would notice.
MOVED_M = 0.005


class BoxNews:
    """`update(success, object_state)` for each judgement, in order: LANDED, LEFT or None.

    LANDED once when the success function first says the cube is in the box; then, while it still says
    so, the place it lies follows the cube (one creeping at rest is never news); LEFT once the cube
    is farther than `moved_m` from that place. After LEFT, the next success is a new landing."""

    def __init__(self, moved_m: float = MOVED_M):
        self.moved_m = moved_m
        self._lay_xyz_m: tuple[float, ...] | None = None  # where the cube last lay at rest in the box; None: not in it

    @property
    def in_box(self) -> bool:
        return self._lay_xyz_m is not None

    def update(self, success: bool, object_state: Sequence[float]) -> str | None:
        """The news of one judgement of the success function and the object_state it judged (cube_to_box's
        OBJECT_STATE_NAMES order), or None."""
        cube_xyz_m = tuple(float(value) for value in object_state[0:3])
        if success:
            news = None if self.in_box else LANDED
            self._lay_xyz_m = cube_xyz_m
            return news
        if self._lay_xyz_m is not None and math.dist(cube_xyz_m, self._lay_xyz_m) > self.moved_m:
            self._lay_xyz_m = None
            return LEFT
        return None

    def forget(self) -> None:
        """The scene was laid out again: the cube is out of the box, and that is no news."""
        self._lay_xyz_m = None
