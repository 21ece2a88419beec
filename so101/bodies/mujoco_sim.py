"""The SO-101 in MuJoCo, behind the same small surface as `so101.bodies.pybullet_sim.SO101Sim`.

Targets and states in degrees, in `so101.robot.ACTUATED_JOINTS` order; `step(count)`
advances `count` periods of the node's tick; `render_rgb` draws offscreen; `close()` is
safe twice. The model is TheRobotStudio's MJCF from `so101 assets`: position actuators
of the STS3215 class (kp 17.8, force ±3.35 N·m) and joint damping 0.60 N·m·s/rad,
armature and friction loss. The scene (so101.bodies.mujoco_model) adds what PyBullet's
has, a ground plane at z = 0 and a light, and collides the meshes' convex hulls; a body
that draws no pictures leaves the visual meshes out.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import numpy.typing as npt

from so101 import assets
from so101.bodies.camera import DEFAULT_CAMERA, WRIST_CAMERA_NAME, Camera, WristCamera, check_picture
from so101.bodies.camera_meshes import camera_meshes
from so101.bodies.mujoco_model import collision_hulls, scene_model
from so101.bodies.command_path import CommandPath
from so101.bodies.looks import DEFAULT_LOOKS
from so101.bodies.physics import DEFAULT_PHYSICS, NOMINAL, Physics, physics_for, physics_ranges
from so101.bodies.protocol import BodyName, RgbImage, SceneTask, TaskScene
from so101.bodies.settings import MuJoCoSettings, NodeSettings
from so101.runtime.display import DisplayError, resolve_mode
from so101.robot import ACTUATED_JOINTS, HOME_POSE_DEG, goal_deg
from so101.runtime.dataflow import TICK_PERIOD_S
from so101.bodies.window import WINDOW_SHOWING, Window

import mujoco  # after so101.bodies.mujoco_model, which chooses its OpenGL back end

# The Debian packages EGL drawing needs (docs/install.md names them, .ci/run installs them).
EGL_PACKAGES = "libegl1 libegl-mesa0 libgl1-mesa-dri"

FloatArray = npt.NDArray[np.float64]


# The MJCF's servos close 63% of a small step's gap in 68-80 ms, and faster as about kp^-0.65 (at kp times 0.5,
# 1, 2, 4: about 120, 75, 48 and 32 ms). A time constant asks for kp times (82 ms / it)^1.55, at most 8: the six
# joints then take 0.85-1.15 times it, 30-120 ms (tests/test_physics.py).
MJCF_TIME_CONSTANT_S = 0.082
MJCF_TIME_CONSTANT_POWER = 1.55
MAX_STIFFNESS = 8.0


def servo_stiffness(servos: Physics) -> float:
    """The actuators' kp, times the MJCF's: `servo_stiffness`, or what gives the physics' time constant."""
    if servos.servo_time_constant_s is None:
        return servos.servo_stiffness
    return min(MAX_STIFFNESS, float((MJCF_TIME_CONSTANT_S / servos.servo_time_constant_s) ** MJCF_TIME_CONSTANT_POWER))


class SO101MuJoCo:
    """An SO-101 on a fixed base in MuJoCo, stepped by hand.

    joint_damping_n_m_s None keeps the MJCF's damping (0.60 N·m·s/rad, the STS3215
    class); a number sets every joint's (exercise 2: 0 swings). MuJoCo steps at the
    MJCF's 2 ms; a tick period is a whole number of those steps.

    `mode` is the display mode asked for (auto, gui, direct); `display_mode` the one it got.
    `renders` False: a body that draws no pictures, compiled without the visual meshes.
    `task` puts that task's scene (it makes it: so101.bodies.protocol.SceneTask) on the floor, laid out from `seed`, and switches
    the gripper's jaw pads on (so101.bodies.jaw_pads); None: the arm alone.
    `physics` "varied" (or a ranges file) draws each layout's physics from its seed (so101.bodies.physics): the
    cube, the actuators' kp, the joints' damping, the gripper's force range, and the command path (its speed limit
    moves the goals no faster: a position actuator has no limit of its own). "fixed" is its nominal point
    (`NOMINAL`: the MJCF's servos, the gripper's 3.35 N·m) without a speed limit, as the MJCF has none.
    `light_pictures` draws the cameras' meshes (so101.bodies.camera_meshes), without shadows,
    multisampling, reflections and skybox: on Mesa's software renderer these cost far more than
    a picture a policy learns from needs (`so101 bench --cameras` measures it).
    """

    kind: BodyName = "mujoco"

    def __init__(
        self,
        mode: str = "auto",
        time_step_s: float = 0.004,
        assets_dir: Path | str | None = None,
        log: Callable[[str], None] = print,
        joint_damping_n_m_s: float | None = None,
        renders: bool = True,
        task: SceneTask | None = None,
        seed: int = 0,
        light_pictures: bool = False,
        physics: str = DEFAULT_PHYSICS,
        looks: str = DEFAULT_LOOKS,  # the window's: each layout's colours and light, as the pictures have them
    ):
        if joint_damping_n_m_s is not None and not joint_damping_n_m_s >= 0:
            raise ValueError(f"joint damping must be a number >= 0 N·m·s/rad, got {joint_damping_n_m_s!r}")
        physics_ranges(physics)  # an unknown mode or a ranges file that makes no sense: refused in one line
        # A missing file gives our message, not MuJoCo's.
        mjcf = assets.mjcf_path(None if assets_dir is None else Path(assets_dir))
        self.display_mode, notice = resolve_mode(mode)
        if notice:
            log(notice)
        # Without pictures the visual meshes stay out: they are most of the model, and the
        # window, when there is one, is another process with its own model.
        meshes = camera_meshes(mjcf.parent, log) if renders and light_pictures else None
        self.model = scene_model(mjcf, collision_hulls(mjcf, log), visual=renders, task=task, camera_meshes=meshes)
        self.data = mujoco.MjData(self.model)
        self.model_step_s = float(self.model.opt.timestep)
        self.joint_names = [self.model.joint(i).name for i in range(self.model.njnt)]
        self._qpos = [int(self.model.joint(joint.name).qposadr[0]) for joint in ACTUATED_JOINTS]
        self._qvel = [int(self.model.joint(joint.name).dofadr[0]) for joint in ACTUATED_JOINTS]
        if joint_damping_n_m_s is not None:
            self.model.dof_damping[self._qvel] = float(joint_damping_n_m_s)
        self._actuators = [int(self.model.actuator(joint.name).id) for joint in ACTUATED_JOINTS]
        # What varied physics scales, as the model (and joint_damping_n_m_s) has it.
        self._own_kp = self.model.actuator_gainprm[self._actuators, 0].copy()
        self._own_damping = self.model.dof_damping[self._qvel].copy()
        self._own_force_range = self.model.actuator_forcerange[self._actuators].copy()
        self.physics_mode = physics
        self.physics: Physics | None = None  # varied physics' draw; None: fixed, the servos `NOMINAL`
        self._command = CommandPath(NOMINAL, HOME_POSE_DEG, slews=False)
        self.renders = renders
        self.light_pictures = light_pictures
        self._renderer: Any = None  # a mujoco.Renderer once render_rgb has drawn
        self.steps = 0
        # GUI mode: MuJoCo's viewer in a process of its own, mirroring the angles (so101/gui/mujoco_viewer.py).
        self._window: Window | None = None
        if self.display_mode == "gui":
            self._window = Window(["so101.gui.mujoco_viewer", "--mjcf", str(mjcf), *(["--task", task.name] if task else [])],
                                  on_showing=lambda: log(WINDOW_SHOWING),
                                  object_values=len(task.object_state_names) if task else 0, looks=looks, physics=physics)
        self.set_time_step_s(time_step_s)
        self.set_targets_deg(HOME_POSE_DEG)
        mujoco.mj_forward(self.model, self.data)
        self.scene: TaskScene | None = None if task is None else task.mujoco_scene(self.model, self.data, seed)
        self.layout_seed: int | None = None if task is None else seed  # the window draws its looks and cube
        if self.scene is not None and physics != DEFAULT_PHYSICS:
            self.reset_task(seed)
        else:  # the arm alone (a replay under a ranges file: its servos and command path)
            self._take_physics(physics_for(physics, seed))

    @classmethod
    def from_settings(cls, settings: MuJoCoSettings, node: NodeSettings, task: SceneTask | None = None,
                      log: Callable[[str], None] = print) -> "SO101MuJoCo":
        """The simulation node's body: the joint damping asked for, a window as `node` asks, no visual meshes
        (the node's pictures are drawn by so101.bodies.task_cameras), and the tick's step."""
        return cls(
            mode=node.display_mode, time_step_s=TICK_PERIOD_S, assets_dir=settings.assets_dir, log=log,
            joint_damping_n_m_s=settings.joint_damping_n_m_s,
            renders=False,  # the node's pictures are so101.bodies.task_cameras'
            task=task, seed=node.seed, physics=node.physics, looks=node.looks,
        )

    # -- control ---------------------------------------------------------------------
    def start_targets_deg(self) -> tuple[float, ...]:
        """Home, as in PyBullet's simulation."""
        return HOME_POSE_DEG

    def set_targets_deg(self, targets_deg: Sequence[float]) -> None:
        """Goal angles in degrees for all six actuated joints (arm 0-4, gripper); with varied physics they
        go through its command path (its delay, speed limit and calibration)."""
        self._command.send(goal_deg(targets_deg), self.sim_time_s)
        if not self._command.slews:  # the goal now, unless it waits out a delay: step() then takes all at once
            self.data.ctrl[self._actuators] = np.radians(self._command.goal_at(self.sim_time_s, self.time_step_s))

    def reset_task(self, seed: int) -> None:
        """The task's scene laid out from `seed`, and the arm at home, still, its goal home (with varied
        physics, `seed`'s physics from now on, and home where the arm believes it is)."""
        if self.scene is None:
            raise ValueError("this simulation runs no task (start it with one: --task)")
        self._take_physics(physics_for(self.physics_mode, seed))
        self.data.qpos[self._qpos] = np.radians(self._command.goal_deg)
        self.data.qvel[self._qvel] = 0.0
        self.data.ctrl[self._actuators] = np.radians(self._command.goal_deg)
        self.scene.lay_out_seed(seed, self.physics)  # also recomputes the kinematics
        self.layout_seed = seed

    def _take_physics(self, physics: Physics | None) -> None:
        """The actuators, the joints and the command path as `physics` has them (None: fixed, `NOMINAL`)."""
        self.physics = physics
        servos = NOMINAL if physics is None else physics
        model, actuators = self.model, self._actuators
        stiffness = servo_stiffness(servos)
        model.actuator_gainprm[actuators, 0] = self._own_kp * stiffness
        model.actuator_biasprm[actuators, 1] = -self._own_kp * stiffness
        model.dof_damping[self._qvel] = self._own_damping * servos.servo_damping
        model.actuator_forcerange[actuators] = self._own_force_range
        model.actuator_forcerange[actuators[-1]] = (-servos.gripper_torque_nm, servos.gripper_torque_nm)
        # Fixed physics keeps the MJCF's actuators, which have no speed limit: a goal moved at the course's 3 rad/s
        # trails it by ~14° on MuJoCo's slower servo, and the grasp's margins shrink (docs/loop/physics.md).
        self._command = CommandPath(servos, HOME_POSE_DEG, slews=physics is not None)
        self.data.ctrl[actuators] = np.radians(self._command.goal_deg)

    def joint_damping_n_m_s(self) -> float:
        """The joints' damping (one value for all, as the MJCF's STS3215 class and this class set it)."""
        return float(self.model.dof_damping[self._qvel[0]])

    def targets_deg(self) -> FloatArray:
        return np.degrees(np.asarray(self.data.ctrl[self._actuators], dtype=np.float64))

    def set_time_step_s(self, time_step_s: float) -> None:
        """The period of one `step()`: a whole number of the model's own steps."""
        if not time_step_s > 0:
            raise ValueError(f"time step must be a positive number of seconds, got {time_step_s!r}")
        self.substeps = max(1, round(time_step_s / self.model_step_s))
        self.time_step_s = self.substeps * self.model_step_s

    def step(self, count: int = 1) -> None:
        """Advance the physics by `count` periods of `time_step_s`, the command path's goals each period."""
        left = count
        while left and not self._command.settled:  # a goal on its way: the path's goal each period
            self.data.ctrl[self._actuators] = np.radians(self._command.goal_at(self.sim_time_s, self.time_step_s))
            mujoco.mj_step(self.model, self.data, nstep=self.substeps)
            self.steps += 1
            left -= 1
        if left:  # the goals where they are wanted: the rest at once
            mujoco.mj_step(self.model, self.data, nstep=left * self.substeps)
            self.steps += left
        if self._window is not None and self._window.due():
            self._window.show(self.data.qpos[self._qpos], None if self.scene is None else self.scene.object_state(),
                              self.layout_seed)

    # -- state -----------------------------------------------------------------------
    def joint_angles_deg(self) -> FloatArray:
        """Measured angles in degrees, arm joints 0-4 then the gripper (varied physics: as its calibration reports them)."""
        return self._command.reported(np.degrees(np.asarray(self.data.qpos[self._qpos], dtype=np.float64)))

    def joint_velocities_deg_s(self) -> FloatArray:
        return np.degrees(np.asarray(self.data.qvel[self._qvel], dtype=np.float64))

    @property
    def sim_time_s(self) -> float:
        return self.steps * self.time_step_s

    # -- pictures --------------------------------------------------------------------
    def show_pose_deg(self, angles_deg: Sequence[float]) -> None:
        """Put the joints at these six angles at once, without physics: a pose to draw (the camera node)."""
        self.data.qpos[self._qpos] = np.radians(goal_deg(angles_deg))
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_camlight(self.model, self.data)  # the cameras fixed to bodies (a task's wrist camera) follow

    def render_rgb(self, width: int = 640, height: int = 480, camera: Camera | WristCamera = DEFAULT_CAMERA) -> RgbImage:
        """The scene as an RGB image, uint8 of shape (height, width, 3), drawn offscreen from `camera`
        (the orbiting one, or the one on the gripper: a task's scene has it)."""
        self._render_setup(width, height, camera)
        return np.array(self._renderer.render(), dtype=np.uint8)

    def render_geoms(self, width: int, height: int, camera: Camera | WristCamera = DEFAULT_CAMERA) -> npt.NDArray[np.int32]:
        """Which geom each pixel shows, int32 of shape (height, width), -1 where none: render_rgb's picture
        as MuJoCo's segmentation draws it (a camera's fit compares the arm's outline with a picture's)."""
        self._render_setup(width, height, camera)
        self._renderer.enable_segmentation_rendering()
        try:
            drawn = self._renderer.render()
        finally:
            self._renderer.disable_segmentation_rendering()
        ids = np.asarray(drawn[:, :, 0], dtype=np.int32)
        return np.where(np.asarray(drawn[:, :, 1]) == int(mujoco.mjtObj.mjOBJ_GEOM), ids, -1).astype(np.int32)

    def _render_setup(self, width: int, height: int, camera: Camera | WristCamera) -> None:
        """The renderer at this size, its scene updated for `camera`: what render_rgb and render_geoms draw."""
        check_picture(self.renders, width, height)
        if isinstance(camera, WristCamera) and self.scene is None:
            raise ValueError("the wrist camera is a task's: start the simulation with a task")
        if self._renderer is None or (self._renderer.width, self._renderer.height) != (width, height):
            self._close_renderer()
            self.model.vis.global_.offwidth = max(self.model.vis.global_.offwidth, width)
            self.model.vis.global_.offheight = max(self.model.vis.global_.offheight, height)
            if self.light_pictures:
                self.model.vis.quality.offsamples = 0
            try:
                self._renderer = mujoco.Renderer(self.model, height, width)
            except Exception as error:  # noqa: BLE001 - MuJoCo's GL set-up fails in several ways
                raise DisplayError(
                    f"MuJoCo cannot draw offscreen ({type(error).__name__}: {error}); "
                    f"without a display it needs EGL: apt-get install {EGL_PACKAGES}"
                ) from None
            if self.light_pictures:
                for flag in (mujoco.mjtRndFlag.mjRND_SHADOW, mujoco.mjtRndFlag.mjRND_REFLECTION,
                             mujoco.mjtRndFlag.mjRND_SKYBOX):
                    self._renderer.scene.flags[flag] = False
        if isinstance(camera, WristCamera):
            self._renderer.update_scene(self.data, WRIST_CAMERA_NAME)
            return
        view = mujoco.MjvCamera()
        view.lookat[:] = camera.target_xyz_m
        view.distance = camera.distance_m
        # PyBullet's yaw 0 looks along +y, MuJoCo's azimuth 90 does; both pitch down when negative.
        view.azimuth = camera.yaw_deg + 90.0
        view.elevation = camera.pitch_deg
        self._renderer.update_scene(self.data, view)
        if camera.roll_deg:  # the free camera is level: its up turned about its line of sight
            _, _, _, up = camera.axes()
            for eye in self._renderer.scene.camera:
                eye.up[:] = up

    # -- life cycle ------------------------------------------------------------------
    def drawn_scene(self) -> Any:
        """The scene (a mujoco.MjvScene) of the picture render_rgb drew last (its camera), to project points onto it."""
        if self._renderer is None:
            raise RuntimeError("no picture drawn yet: call render_rgb first")
        return self._renderer.scene

    def _close_renderer(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def close(self) -> None:
        """Close the window and let go of the renderer; safe to call twice."""
        if self._window is not None:
            self._window.close()
            self._window = None
        self._close_renderer()

    def __enter__(self) -> "SO101MuJoCo":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
