"""What a body of the SO-101 is to its node: the surface the shared loop (so101/bodies/node_loop.py) drives.

`SO101Sim` (PyBullet), `SO101MuJoCo` and `SO101Real` (six servos on a bus) implement it.
Angles are degrees, six of them in `so101.robot.ACTUATED_JOINTS` order: the five arm
joints, then the gripper. The real arm differs only where hardware must: it starts
where it stands, a read can fail (no angles that tick), and it has no camera and no task.
A simulation started with a task (so101.tasks) has its `scene`: the objects on the floor.
"""

from __future__ import annotations

from typing import Literal, Protocol, Sequence, Union

import numpy as np
import numpy.typing as npt

from so101.bodies.camera import DEFAULT_CAMERA, Camera, WristCamera
from so101.tasks.cube_to_box import CubeToBox, Layout

BodyName = Literal["pybullet", "mujoco", "real"]

# A simulator hands back numpy arrays, the real arm a tuple of what it read.
AnglesDeg = Union[npt.NDArray[np.float64], tuple[float, ...]]
RgbImage = npt.NDArray[np.uint8]
ObjectState = npt.NDArray[np.float32]


class BodyFailed(Exception):
    """A body that cannot start or go on (the real arm's bus, a closed window); str() is one line for the user."""


class TaskScene(Protocol):
    """A task's objects in a simulation (so101.tasks.pybullet_scene, so101.tasks.mujoco_scene)."""

    @property
    def task(self) -> CubeToBox:
        """The task whose objects these are (its facts, its object_state names, its success function)."""

    @property
    def layout(self) -> Layout:
        """The layout the scene was last laid out from (its seed among it)."""

    def object_state(self) -> ObjectState:
        """The objects' poses now, float32, in the task's `object_state_names` order (metres, base frame)."""

    def cube_speed_m_s(self) -> float:
        """How fast the cube moves now, m/s (the success function's "at rest")."""

    def succeeded(self) -> bool:
        """The task's success function, on the objects as they are now."""


class Body(Protocol):
    @property
    def kind(self) -> BodyName:
        """Which body this is: the so101.bodies.registry name."""

    @property
    def display_mode(self) -> str | None:
        """"gui" (a window shows the arm) or "direct" (headless); None for hardware, which has no display."""

    @property
    def steps(self) -> int:
        """Steps taken so far (the real arm: bus exchanges), for the tick log and the image rate."""

    def start_targets_deg(self) -> tuple[float, ...]:
        """The targets before any command: home for a simulation, where the real arm stands."""

    @property
    def scene(self) -> TaskScene | None:
        """The task's objects; None without a task (the real arm: always)."""

    def reset_task(self, seed: int) -> None:
        """The scene laid out from `seed` and the arm at home, still, its targets home; ValueError without a task."""

    def set_targets_deg(self, targets_deg: Sequence[float]) -> None:
        """New goals for all six joints; the next `step` applies them."""

    def set_time_step_s(self, time_step_s: float) -> None:
        """The period one `step` advances (the tick's), before the first step."""

    def step(self, count: int = 1) -> None:
        """Advance `count` time steps (the real arm: one bus exchange, whatever `count`)."""

    def joint_angles_deg(self) -> AnglesDeg | None:
        """The six angles now; None when this tick's read failed (the real arm's bus)."""

    def render_rgb(self, width: int, height: int, camera: Camera | WristCamera = DEFAULT_CAMERA) -> RgbImage:
        """A picture of the arm from `camera`, uint8 of shape (height, width, 3); a body without a camera
        raises ValueError."""

    def close(self) -> None:
        """Let go of everything the body holds (a physics client, a window, servo torque); safe twice."""
