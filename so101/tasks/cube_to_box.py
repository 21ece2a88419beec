"""`cube_to_box`: a cube on the floor to be put into an open box. Its facts, layouts and success.

One description for every simulator: PyBullet (so101.tasks.pybullet_scene) and MuJoCo
(so101.tasks.mujoco_scene) build the scene from these numbers, and nothing else. A simulated body
asks the task for its scene through the hooks of so101.bodies.protocol.SceneTask (`pybullet_scene`,
`add_to_mujoco_spec`, `mujoco_scene`): the bodies know no task. Frame: the
arm's base frame, which both simulators put at their world origin: x forward (where the arm
reaches at home), y to its left, z up, the floor at z = 0. Metres, kilograms, radians.

A layout is drawn from a seed (`layout`): the cube's centre uniformly in radius and bearing
within an annular sector in front of the arm, to its right, and its yaw uniformly within
±45° (a cube looks the same every 90°). The box stands in one place, to the arm's left. The
sector and the box's footprint are apart by construction (`tests/test_tasks.py` holds it for
every corner of the sector), so no seed puts the cube in the box. Python's `random.Random`
draws the numbers: its sequence for a seed is the same on every platform and Python 3 release.

Success (`succeeded`) is the cube at rest inside the box: its centre within the box's inner
walls, low enough to lie on the box's floor (flat, or tilted against a wall: not held above it),
and moving slower than `REST_SPEED_M_S`.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Iterable, Sequence

from so101.tasks.objects import OBJECT_STATE_NAMES, Box, Cube, Layout, SpawnSector

if TYPE_CHECKING:
    from so101.bodies.jaw_pads import JawPad
    from so101.tasks.mujoco_scene import MuJoCoScene
    from so101.tasks.pybullet_scene import PyBulletScene

NAME = "cube_to_box"

# Slower than this, the cube is at rest (a cube that lands bounces for a few tenths of a second faster).
REST_SPEED_M_S = 0.01
# A cube in the box lies on its floor: its centre at most this much higher than lying flat there. Tilted
# against a wall it is up to 5.2 mm higher (a 25 mm cube on an edge); held still 15 mm above the floor,
# where the jaws could let it go, it is not in the box yet.
ON_FLOOR_SLACK_M = 0.008


@dataclass(frozen=True)
class CubeToBox:
    """The task's facts: what is on the floor, where a cube may start, and when it is done."""

    cube: Cube = Cube()
    box: Box = Box()
    sector: SpawnSector = SpawnSector()
    name: str = NAME
    instruction: str = "put the cube in the box"  # an episode's task text in a dataset: what a policy is told
    object_state_names: tuple[str, ...] = OBJECT_STATE_NAMES

    def layout(self, seed: int) -> Layout:
        """The layout of `seed` (a whole number >= 0): the same on every machine and simulator."""
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ValueError(f"a seed is a whole number >= 0, got {seed!r}")
        draw = random.Random(seed)
        radius = draw.uniform(*self.sector.radius_m)
        bearing = draw.uniform(*self.sector.bearing_rad)
        yaw = draw.uniform(*self.sector.yaw_rad)
        cube_xyz = (radius * math.cos(bearing), radius * math.sin(bearing), self.cube.half_size_m)
        return Layout(seed, cube_xyz, yaw, (*self.box.xy_m, 0.0))

    def succeeded(self, cube_xyz_m: Sequence[float], box_xyz_m: Sequence[float], cube_speed_m_s: float) -> bool:
        """The cube at rest inside the box: its centre within the inner walls, lying on the box's floor
        (ON_FLOOR_SLACK_M), and slower than REST_SPEED_M_S. On the rim, outside, still falling or held
        above the floor, it is not."""
        dx, dy, dz = (cube - box for cube, box in zip(cube_xyz_m, box_xyz_m))
        inner = self.box.inner_half_m
        lying_z = self.box.floor_thickness_m + self.cube.half_size_m
        return (abs(dx) < inner and abs(dy) < inner and dz < lying_z + ON_FLOOR_SLACK_M
                and cube_speed_m_s < REST_SPEED_M_S)

    def state_succeeded(self, object_state: Iterable[float], cube_speed_m_s: float) -> bool:
        """`succeeded` on an object_state (OBJECT_STATE_NAMES' order), as the simulations publish it."""
        values = [float(value) for value in object_state]
        return self.succeeded(values[0:3], values[7:10], cube_speed_m_s)

    def reward(self, success: bool) -> float:
        """`next.reward` of a frame: 1 where the cube is in the box, else 0 (a sparse reward, as
        LeRobot's simulation datasets carry it)."""
        return 1.0 if success else 0.0

    # -- the scene, made for a body (so101.bodies.protocol.SceneTask); each engine imported on first use

    def pybullet_scene(self, client: int, seed: int) -> PyBulletScene:
        from so101.tasks.pybullet_scene import PyBulletScene

        return PyBulletScene(client, self, self.layout(seed))

    def add_to_mujoco_spec(self, spec: Any, pads: tuple[JawPad, ...]) -> None:
        from so101.tasks.mujoco_scene import add_to_spec

        add_to_spec(spec, self, pads)

    def mujoco_scene(self, model: Any, data: Any, seed: int) -> MuJoCoScene:
        from so101.tasks.mujoco_scene import MuJoCoScene

        return MuJoCoScene(model, data, self, self.layout(seed))


CUBE_TO_BOX = CubeToBox()
