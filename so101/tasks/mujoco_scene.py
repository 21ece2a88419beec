"""A task's scene in MuJoCo: the cube and the box of so101.tasks.cube_to_box, added to the arm's MjSpec.

`add_to_spec` puts them into the scene before it compiles (so101.bodies.mujoco_model.scene_model)
and switches the jaw pads on (so101.bodies.jaw_pads); `MuJoCoScene` lays them out and reads them.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np
import numpy.typing as npt

from so101.bodies import mujoco_model  # noqa: F401  (first: it chooses MuJoCo's OpenGL back end)
from so101.bodies.camera import WRIST_CAMERA, WRIST_CAMERA_NAME, WristCamera
from so101.bodies.camera import wrist_placement
from so101.bodies.jaw_pads import JawPad
from so101.bodies.physics import Physics
from so101.tasks.objects import Cube, Layout, SceneFacts, cube_with, on_the_floor

import mujoco  # noqa: E402

CUBE_BODY = "cube"
BOX_BODY = "box"
GRIPPER_BODY = "gripper"  # the MJCF's; its frame is the URDF's gripper_link
# MuJoCo's rolling and torsional friction coefficients beside the sliding one (its defaults).
SPIN_ROLL_FRICTION = (0.005, 0.0001)
NOSLIP_ITERATIONS = 3


def add_to_spec(spec: Any, task: SceneFacts, pads: tuple[JawPad, ...]) -> None:
    """The cube (a free body) and the box (a fixed body of five plates) into `spec`, and the jaw pads
    on, as `pads` has them (so101.bodies.jaw_pads: the MJCF's, grown)."""
    # MuJoCo's soft contacts let a held cube slide down the pads (measured: 6 mm in 5 s, and out of
    # the jaws on a longer hold); its no-slip solver's passes stop that.
    spec.option.noslip_iterations = NOSLIP_ITERATIONS
    by_name = {pad.name: pad for pad in pads}
    for geom in spec.geoms:
        if geom.name in by_name:
            geom.contype, geom.conaffinity = 1, 1
            geom.pos, geom.size = list(by_name[geom.name].pos_m), list(by_name[geom.name].half_size_m)
    add_wrist_camera(spec, WRIST_CAMERA)
    cube = task.cube
    cube_body = spec.worldbody.add_body(name=CUBE_BODY, pos=[0, 0, cube.half_size_m])
    cube_body.add_freejoint(name=CUBE_BODY)
    cube_body.add_geom(
        name=CUBE_BODY, type=mujoco.mjtGeom.mjGEOM_BOX, size=[cube.half_size_m] * 3, mass=cube.mass_kg,
        rgba=list(cube.rgba), friction=[cube.friction, *SPIN_ROLL_FRICTION], condim=4,
    )
    box_body = spec.worldbody.add_body(name=BOX_BODY, pos=[*task.box.xy_m, 0.0])
    for index, (centre, half_extents) in enumerate(task.box.plates()):
        box_body.add_geom(
            name=f"{BOX_BODY}_{index}", type=mujoco.mjtGeom.mjGEOM_BOX, pos=list(centre), size=list(half_extents),
            rgba=list(task.box.rgba), friction=[task.box.friction, *SPIN_ROLL_FRICTION],
        )


def add_wrist_camera(spec: Any, camera: WristCamera) -> None:
    """`camera` as a camera of the gripper's body (MuJoCo's look along their -z, their +y up)."""
    pos, quat = wrist_placement(camera)
    spec.body(GRIPPER_BODY).add_camera(name=WRIST_CAMERA_NAME, pos=list(pos), quat=list(quat), fovy=camera.fov_deg)


class MuJoCoScene:
    """The compiled scene's cube and box, for `task`, laid out as `layout`."""

    def __init__(self, model: Any, data: Any, task: SceneFacts, layout: Layout):
        self.model, self.data, self.task = model, data, task
        joint = model.joint(CUBE_BODY)
        self._cube_qpos = int(joint.qposadr[0])
        self._cube_qvel = int(joint.dofadr[0])
        self._cube_geom, self._cube_body = int(model.geom(CUBE_BODY).id), int(model.body(CUBE_BODY).id)
        self._box_body = int(model.body(BOX_BODY).id)
        self.cube = task.cube
        self.lay_out(layout)

    def lay_out_seed(self, seed: int, physics: Physics | None = None) -> None:
        """The layout of `seed`, its cube as `physics` makes it (its size, mass and friction)."""
        cube = cube_with(self.task.cube, physics)
        if cube != self.cube:
            self._shape_cube(cube)
        self.lay_out(on_the_floor(self.task.layout(seed), cube))

    def _shape_cube(self, cube: Cube) -> None:
        """The compiled model's cube made `cube`: its box, its bounds (the collision's broad phase reads them),
        its friction, its mass and a solid cube's inertia; then the constants derived from them."""
        model, geom, body, half = self.model, self._cube_geom, self._cube_body, cube.half_size_m
        model.geom_size[geom] = [half] * 3
        model.geom_aabb[geom][3:] = half
        model.geom_rbound[geom] = half * math.sqrt(3.0)
        model.geom_friction[geom][0] = cube.friction
        model.body_mass[body] = cube.mass_kg
        model.body_inertia[body] = [cube.mass_kg * (2 * half) ** 2 / 6] * 3
        # mj_setConst poses the model at qpos0 in `data` to derive them: the state is put back after.
        qpos, qvel, ctrl = self.data.qpos.copy(), self.data.qvel.copy(), self.data.ctrl.copy()
        mujoco.mj_setConst(model, self.data)
        self.data.qpos[:], self.data.qvel[:], self.data.ctrl[:] = qpos, qvel, ctrl
        self.cube = cube

    def lay_out(self, layout: Layout) -> None:
        """The cube and the box where `layout` puts them, the cube still (kinematics recomputed)."""
        self.layout = layout
        self.model.body_pos[self._box_body] = layout.box_xyz_m
        qx, qy, qz, qw = layout.cube_quat_xyzw()
        self.data.qpos[self._cube_qpos:self._cube_qpos + 7] = [*layout.cube_xyz_m, qw, qx, qy, qz]
        self.data.qvel[self._cube_qvel:self._cube_qvel + 6] = 0.0
        mujoco.mj_forward(self.model, self.data)

    def show_object_state(self, state: Sequence[float]) -> None:
        """Put the objects where an object_state says, for drawing (the caller runs mj_kinematics). An
        object_state of zeros (none came yet: no quaternion) leaves them where they are."""
        if not any(state[3:7]):
            return
        x, y, z, qx, qy, qz, qw, box_x, box_y, box_z = (float(value) for value in state[:10])
        self.data.qpos[self._cube_qpos:self._cube_qpos + 7] = [x, y, z, qw, qx, qy, qz]
        self.model.body_pos[self._box_body] = (box_x, box_y, box_z)

    def object_state(self) -> npt.NDArray[np.float32]:
        """The cube's centre and quaternion (x y z w) and the box's position: OBJECT_STATE_NAMES' order."""
        x, y, z, qw, qx, qy, qz = self.data.qpos[self._cube_qpos:self._cube_qpos + 7]
        return np.array([x, y, z, qx, qy, qz, qw, *self.model.body_pos[self._box_body]], dtype=np.float32)

    def cube_speed_m_s(self) -> float:
        return float(np.linalg.norm(self.data.qvel[self._cube_qvel:self._cube_qvel + 3]))

    def succeeded(self) -> bool:
        return self.task.state_succeeded(self.object_state(), self.cube_speed_m_s())
