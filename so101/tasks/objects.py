"""The objects a task puts on the floor, as plain facts: a cube, an open box, the sector a cube
starts in, and a layout (where one episode starts).

The scenes (so101.tasks.pybullet_scene, so101.tasks.mujoco_scene) build from these and from
`SceneFacts`, what they read of a task; the task (so101.tasks.cube_to_box) makes its scenes, so
this module sits below both. Frame and units as so101.tasks.cube_to_box says.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Iterable, Protocol

from so101.bodies.physics import Physics

# The names of `object_state` (so101/bodies/node_loop.py), in its order: the cube's centre and
# orientation (a quaternion, x y z w), the box's position (its footprint's centre, on the floor).
OBJECT_STATE_NAMES: tuple[str, ...] = (
    "cube.x", "cube.y", "cube.z", "cube.qx", "cube.qy", "cube.qz", "cube.qw", "box.x", "box.y", "box.z",
)

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


def cube_with(cube: Cube, physics: Physics | None) -> Cube:
    """The cube as an episode's physics makes it (so101.bodies.physics: its size, mass and friction); None: as it is."""
    if physics is None:
        return cube
    return replace(cube, half_size_m=physics.cube_half_size_m, mass_kg=physics.cube_mass_kg, friction=physics.cube_friction)


def on_the_floor(layout: Layout, cube: Cube) -> Layout:
    """`layout` with `cube` lying on the floor where it says (a layout is drawn for the task's own cube)."""
    x, y, _ = layout.cube_xyz_m
    return replace(layout, cube_xyz_m=(x, y, cube.half_size_m))


class SceneFacts(Protocol):
    """What a scene reads of its task (so101.tasks.cube_to_box.CubeToBox is one)."""

    @property
    def name(self) -> str: ...

    @property
    def object_state_names(self) -> tuple[str, ...]: ...

    @property
    def cube(self) -> Cube: ...

    @property
    def box(self) -> Box: ...

    def layout(self, seed: int) -> Layout: ...

    def state_succeeded(self, object_state: Iterable[float], cube_speed_m_s: float) -> bool: ...
