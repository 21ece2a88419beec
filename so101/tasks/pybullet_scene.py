"""A task's scene in PyBullet: the cube and the box of so101.tasks.cube_to_box, in one client.

The arm's PyBullet body (so101.bodies.pybullet_sim.SO101Sim) makes one of these when it runs a
task, on its own client, and loads the arm with the jaw pads (so101.bodies.jaw_pads).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import numpy.typing as npt
import pybullet as p

from so101.bodies.physics import Physics
from so101.tasks.objects import Cube, Layout, SceneFacts, cube_with, on_the_floor


class PyBulletScene:
    """The cube (a free body) and the box (fixed, five plates) of `task`, laid out as `layout`."""

    def __init__(self, client: int, task: SceneFacts, layout: Layout):
        self.client = client
        self.task = task
        self.cube = task.cube
        self.cube_id = self._make_cube(self.cube)
        plates = task.box.plates()
        centres = [list(centre) for centre, _ in plates]
        halves = [list(half_extents) for _, half_extents in plates]
        self.box_id: int = p.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=p.createCollisionShapeArray(
                [p.GEOM_BOX] * len(plates), halfExtents=halves, collisionFramePositions=centres, physicsClientId=client),
            baseVisualShapeIndex=p.createVisualShapeArray(
                [p.GEOM_BOX] * len(plates), halfExtents=halves, visualFramePositions=centres,
                rgbaColors=[list(task.box.rgba)] * len(plates), physicsClientId=client),
            physicsClientId=client,
        )
        p.changeDynamics(self.box_id, -1, lateralFriction=task.box.friction, physicsClientId=client)
        self.lay_out(layout)

    def _make_cube(self, cube: Cube) -> int:
        client = self.client
        half = [cube.half_size_m] * 3
        cube_id = int(p.createMultiBody(
            baseMass=cube.mass_kg,
            baseCollisionShapeIndex=p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client),
            baseVisualShapeIndex=p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=list(cube.rgba),
                                                     physicsClientId=client),
            physicsClientId=client,
        ))
        # A friction anchor, as on the jaws (so101.bodies.pybullet_sim): without, a held cube creeps out.
        p.changeDynamics(cube_id, -1, lateralFriction=cube.friction, frictionAnchor=1, physicsClientId=client)
        return cube_id

    @property
    def object_ids(self) -> tuple[int, int]:
        """The objects' bodies in the task's order (the looks' colours): the cube, the box."""
        return self.cube_id, self.box_id

    def lay_out_seed(self, seed: int, physics: Physics | None = None) -> None:
        """The layout of `seed`, its cube as `physics` makes it (a new size: a new body; PyBullet's shapes keep theirs)."""
        cube = cube_with(self.task.cube, physics)
        if cube != self.cube:
            p.removeBody(self.cube_id, physicsClientId=self.client)
            self.cube, self.cube_id = cube, self._make_cube(cube)
        self.lay_out(on_the_floor(self.task.layout(seed), cube))

    def lay_out(self, layout: Layout) -> None:
        """The cube and the box where `layout` puts them, the cube still."""
        self.layout = layout
        p.resetBasePositionAndOrientation(self.box_id, list(layout.box_xyz_m), [0, 0, 0, 1], physicsClientId=self.client)
        p.resetBasePositionAndOrientation(self.cube_id, list(layout.cube_xyz_m), list(layout.cube_quat_xyzw()),
                                          physicsClientId=self.client)
        p.resetBaseVelocity(self.cube_id, [0, 0, 0], [0, 0, 0], physicsClientId=self.client)

    def show_object_state(self, state: Sequence[float]) -> None:
        """Put the objects where an object_state says, without physics: a scene to draw (a window, a camera).
        An object_state of zeros (none came yet: no quaternion) leaves them where they are."""
        if not any(state[3:7]):
            return
        values = [float(value) for value in state]
        p.resetBasePositionAndOrientation(self.cube_id, values[0:3], values[3:7], physicsClientId=self.client)
        p.resetBasePositionAndOrientation(self.box_id, values[7:10], [0, 0, 0, 1], physicsClientId=self.client)

    def object_state(self) -> npt.NDArray[np.float32]:
        """The cube's centre and quaternion (x y z w) and the box's position: OBJECT_STATE_NAMES' order."""
        cube_xyz, cube_quat = p.getBasePositionAndOrientation(self.cube_id, physicsClientId=self.client)
        box_xyz, _ = p.getBasePositionAndOrientation(self.box_id, physicsClientId=self.client)
        return np.array([*cube_xyz, *cube_quat, *box_xyz], dtype=np.float32)

    def cube_speed_m_s(self) -> float:
        linear, _ = p.getBaseVelocity(self.cube_id, physicsClientId=self.client)
        return float(np.linalg.norm(linear))

    def succeeded(self) -> bool:
        return self.task.state_succeeded(self.object_state(), self.cube_speed_m_s())
