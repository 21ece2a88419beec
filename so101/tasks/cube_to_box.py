"""`cube_to_box`: a cube on the floor to be put into an open box. Its facts, layouts and success.

One description for every simulator: PyBullet (so101.tasks.pybullet_scene) and MuJoCo
(so101.tasks.mujoco_scene) build the scene from these numbers, and nothing else. Frame: the
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
from typing import Iterable, Sequence

NAME = "cube_to_box"

# The names of `object_state` (so101/bodies/node_loop.py), in its order: the cube's centre and
# orientation (a quaternion, x y z w), the box's position (its footprint's centre, on the floor).
OBJECT_STATE_NAMES: tuple[str, ...] = (
    "cube.x", "cube.y", "cube.z", "cube.qx", "cube.qy", "cube.qz", "cube.qw", "box.x", "box.y", "box.z",
)

# Slower than this, the cube is at rest (a cube that lands bounces for a few tenths of a second faster).
REST_SPEED_M_S = 0.01
# A cube in the box lies on its floor: its centre at most this much higher than lying flat there. Tilted
# against a wall it is up to 5.2 mm higher (a 25 mm cube on an edge); held still 15 mm above the floor,
# where the jaws could let it go, it is not in the box yet.
ON_FLOOR_SLACK_M = 0.008


@dataclass(frozen=True)
class Cube:
    half_size_m: float = 0.0125  # a 25 mm cube: the jaws open to 40 mm between their pads
    mass_kg: float = 0.03
    friction: float = 1.0  # sliding friction coefficient, both simulators
    rgba: tuple[float, float, float, float] = (0.85, 0.25, 0.2, 1.0)


@dataclass(frozen=True)
class Box:
    """An open box with low walls, fixed to the floor: a floor plate and four walls."""

    xy_m: tuple[float, float] = (0.16, 0.19)  # its footprint's centre, to the arm's left
    outer_half_m: float = 0.06  # 120 mm square outside
    wall_height_m: float = 0.04  # from the floor to the walls' top
    wall_thickness_m: float = 0.005
    floor_thickness_m: float = 0.005
    friction: float = 0.8
    rgba: tuple[float, float, float, float] = (0.25, 0.45, 0.8, 1.0)

    @property
    def inner_half_m(self) -> float:
        return self.outer_half_m - self.wall_thickness_m

    def plates(self) -> list[tuple[tuple[float, float, float], tuple[float, float, float]]]:
        """The box as five solid plates, each (centre, half extents), in the box's own frame (its
        footprint's centre on the floor): the floor plate, then the walls at -x, +x, -y, +y."""
        outer, thick, height, floor = self.outer_half_m, self.wall_thickness_m, self.wall_height_m, self.floor_thickness_m
        wall_centre = outer - thick / 2
        half_height = height / 2
        return [
            ((0.0, 0.0, floor / 2), (outer, outer, floor / 2)),
            ((-wall_centre, 0.0, half_height), (thick / 2, outer, half_height)),
            ((wall_centre, 0.0, half_height), (thick / 2, outer, half_height)),
            ((0.0, -wall_centre, half_height), (outer - thick, thick / 2, half_height)),
            ((0.0, wall_centre, half_height), (outer - thick, thick / 2, half_height)),
        ]


@dataclass(frozen=True)
class SpawnSector:
    """Where a cube's centre may be drawn: radius from the base's axis, bearing from +x toward +y."""

    radius_m: tuple[float, float] = (0.16, 0.26)
    bearing_rad: tuple[float, float] = (math.radians(-55.0), math.radians(10.0))
    yaw_rad: tuple[float, float] = (math.radians(-45.0), math.radians(45.0))

    def corners_xy_m(self) -> list[tuple[float, float]]:
        """The sector's four corners and the middles of its arcs: the points farthest out, nearest in,
        and at each edge, for the reach and overlap checks."""
        points = []
        for radius in self.radius_m:
            for bearing in (*self.bearing_rad, sum(self.bearing_rad) / 2):
                points.append((radius * math.cos(bearing), radius * math.sin(bearing)))
        return points


@dataclass(frozen=True)
class Layout:
    """Where one episode starts: the seed it was drawn from, the cube's centre and yaw, the box's position."""

    seed: int
    cube_xyz_m: tuple[float, float, float]
    cube_yaw_rad: float
    box_xyz_m: tuple[float, float, float]

    def cube_quat_xyzw(self) -> tuple[float, float, float, float]:
        half = self.cube_yaw_rad / 2
        return (0.0, 0.0, math.sin(half), math.cos(half))


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


CUBE_TO_BOX = CubeToBox()
