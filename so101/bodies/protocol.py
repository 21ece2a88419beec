"""What a body of the SO-101 is to its node: the surface the shared loop (so101/bodies/node_loop.py) drives.

`SO101Sim` (PyBullet), `SO101MuJoCo` and `SO101Real` (six servos on a bus) implement it.
Angles are degrees, six of them in `so101.robot.ACTUATED_JOINTS` order: the five arm
joints, then the gripper. The real arm differs only where hardware must: it starts
where it stands, a read can fail (no angles that tick), and it has no camera and no task.
A simulation started with a task has its `scene`: the objects on the floor. The body knows a
task only as `SceneTask` says: the task hands the body its scene (its objects in the body's
engine), so a new task needs no body edited, and nothing here imports so101.tasks.
"""

from __future__ import annotations

from typing import Any, Iterable, Literal, Protocol, Sequence, Union

import numpy as np
import numpy.typing as npt

from so101.bodies.camera import DEFAULT_CAMERA, Camera, WristCamera
from so101.bodies.jaw_pads import JawPad
from so101.bodies.physics import Physics

BodyName = Literal["pybullet", "mujoco", "real"]

# A simulator hands back numpy arrays, the real arm a tuple of what it read.
AnglesDeg = Union[npt.NDArray[np.float64], tuple[float, ...]]
RgbImage = npt.NDArray[np.uint8]
ObjectState = npt.NDArray[np.float32]


class BodyFailed(Exception):
    """A body that cannot start or go on (the real arm's bus, a closed window); str() is one line for the user."""


class SceneLayout(Protocol):
    """Where one episode starts (so101.tasks' layouts): the body needs only its seed."""

    @property
    def seed(self) -> int: ...


class TaskFacts(Protocol):
    """What the shared loop reads of a task: its name, its object_state names, its success function."""

    @property
    def name(self) -> str: ...

    @property
    def object_state_names(self) -> tuple[str, ...]: ...

    def state_succeeded(self, object_state: Iterable[float], cube_speed_m_s: float) -> bool:
        """The success function on an object_state, as the simulations publish it."""


class TaskScene(Protocol):
    """A task's objects in a simulation, made by the task (`SceneTask`) in the body's engine."""

    @property
    def task(self) -> TaskFacts:
        """The task whose objects these are (its name, its object_state names, its success function)."""

    @property
    def layout(self) -> SceneLayout:
        """The layout the scene was last laid out from (its seed among it)."""

    def lay_out_seed(self, seed: int, physics: Physics | None = None) -> None:
        """The objects where the task's layout of `seed` puts them, still; the cube as `physics` makes it
        (so101.bodies.physics; None: the task's own)."""

    def show_object_state(self, state: Sequence[float]) -> None:
        """The objects where an object_state says, without physics: a scene to draw."""

    def object_state(self) -> ObjectState:
        """The objects' poses now, float32, in the task's `object_state_names` order (metres, base frame)."""

    def cube_speed_m_s(self) -> float:
        """How fast the cube moves now, m/s (the success function's "at rest")."""

    def succeeded(self) -> bool:
        """The task's success function, on the objects as they are now."""


class SceneTask(TaskFacts, Protocol):
    """What a simulated body is handed of a task (so101.tasks' tasks are such): its facts, and its
    additions to each engine. The body calls these hooks; the task builds its objects."""

    def pybullet_scene(self, client: int, seed: int) -> TaskScene:
        """The task's objects made in PyBullet client `client`, laid out from `seed`."""

    def add_to_mujoco_spec(self, spec: Any, pads: tuple[JawPad, ...]) -> None:
        """The task's objects (and what they need of the arm: its jaw pads `pads`) added to a
        mujoco.MjSpec before it compiles."""

    def mujoco_scene(self, model: Any, data: Any, seed: int) -> TaskScene:
        """The task's objects in the compiled model `model` (added by `add_to_mujoco_spec`), laid out from `seed`."""


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
        """The scene laid out from `seed` and the arm at home, still, its targets home; ValueError without a task.
        A simulation with varied physics (so101.bodies.physics) takes `seed`'s from here on."""

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
