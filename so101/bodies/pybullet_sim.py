"""The one class that talks to PyBullet: an SO-101 on a ground plane.

Each instance owns its own physics client and passes `physicsClientId` on every
call, so several simulators can live in one process. Angles cross this boundary
in degrees; PyBullet's radians stay inside.
"""

from __future__ import annotations

import ctypes
import math
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import numpy.typing as npt
import pybullet as p
import pybullet_data

from so101 import assets
from so101.bodies import pybullet_hulls
from so101.bodies.camera import DEFAULT_CAMERA, Camera, WristCamera, check_picture
from so101.bodies.camera_meshes import camera_meshes, urdf_for_cameras
from so101.bodies.jaw_pads import jaw_pads, urdf_with_pads
from so101.bodies.command_path import CommandPath
from so101.bodies.looks import DEFAULT_LOOKS
from so101.bodies.physics import DEFAULT_PHYSICS, NOMINAL, Physics, physics_for, physics_ranges
from so101.bodies.protocol import BodyName, RgbImage, SceneTask, TaskScene
from so101.bodies.settings import NodeSettings, PyBulletSettings, check_control_mode
from so101.runtime.display import resolve_mode
from so101.runtime.dataflow import TICK_PERIOD_S
from so101.bodies.pd_servo import (
    DEFAULT_DAMPING_RATIO,
    DEFAULT_NATURAL_FREQ_RAD_S,
    SERVO_TORQUE_LIMIT_NM,
    pd_gains,
    pd_torque_nm,
)
from so101.robot import (
    ACTUATED_JOINTS,
    ARM_JOINTS,
    COURSE_LINK_DAMPING,
    GRIPPER,
    COURSE_MAX_VELOCITY_RAD_S,
    HOME_POSE_DEG,
    goal_deg,
)
from so101.bodies.window import WINDOW_SHOWING, Window

JOINT_TYPE_NAMES = {
    p.JOINT_REVOLUTE: "revolute",
    p.JOINT_PRISMATIC: "prismatic",
    p.JOINT_SPHERICAL: "spherical",
    p.JOINT_PLANAR: "planar",
    p.JOINT_FIXED: "fixed",
}

M_MMAP_THRESHOLD = -3  # glibc's mallopt parameter number

FloatArray = npt.NDArray[np.float64]
# The link that carries the fixed jaw (and its pad): the child of wrist_roll.
GRIPPER_LINK_INDEX = ARM_JOINTS[-1].index


def release_freed_memory() -> None:
    """Make glibc hand large freed blocks back to the system at once (a process-wide setting).

    Loading the arm from its full meshes (deriving the hull files, or without them) computes
    a convex hull per collision mesh and frees it: up to 79 MB for the largest. glibc raises
    its mmap threshold as blocks are freed, so it keeps them in its heap; with the threshold
    fixed at 64 KiB they are unmapped when freed, and the next mesh does not pile on top.
    Elsewhere than glibc, nothing to do.
    """
    try:
        libc = ctypes.CDLL("libc.so.6")
    except OSError:
        return
    libc.mallopt(M_MMAP_THRESHOLD, 64 * 1024)


# PyBullet's own POSITION_CONTROL gains and force, when none are given (pybullet.c): the course's call gives none.
# Physics scales the gains; the arm's joints keep the force, the gripper's is the physics' torque.
POSITION_GAIN = 0.1
VELOCITY_GAIN = 1.0
MOTOR_FORCE_N_M = 100000.0


@dataclass(frozen=True)
class JointInfo:
    """A row of `getJointInfo`, as PyBullet reports it: limits in radians, max_velocity in rad/s, max_force in N·m."""

    index: int
    name: str
    type: str
    lower_rad: float
    upper_rad: float
    max_force: float
    max_velocity: float


class SO101Sim:
    """An SO-101 arm on a fixed base, stepped by hand.

    targets and states are in degrees, in the order of `so101.robot.ACTUATED_JOINTS`:
    the five arm joints, then the gripper.

    control_mode "position" (default) makes the course's calls for each new goal: per joint,
    `setJointMotorControl2(POSITION_CONTROL, targetPosition=goal, maxVelocity=3.0)` with
    PyBullet's default force and gains, so the arm moves exactly as the course's does.
    "servo" is a PD torque servo (gains from ζ, ωn and each joint's inertia, torques
    clipped to servo_torque_limit_nm) that takes the goal as a step, so
    max_velocity_rad_s does not apply to it.

    renders=False leaves out PyBullet's CPU renderer (render_rgb then refuses): it keeps
    a copy of every visual mesh, 68 MB of this arm's, that only pictures need.

    hull_collisions=True collides the arm through the hull files derived from the model
    (so101.bodies.pybullet_hulls; derived now if missing): the same hulls PyBullet builds
    from the full meshes, without loading those. False collides the full meshes, as the
    course does; the arm moves the same (tests/test_course_motion.py). Pictures always
    show the full meshes.

    `task` puts that task's scene (it makes it: so101.bodies.protocol.SceneTask) on the floor, laid out from `seed`, and gives
    the gripper its jaw pads (so101.bodies.jaw_pads); None: the arm alone, as in the course.

    `physics` "varied" (or a ranges file) draws each layout's physics from its seed (so101.bodies.physics): the
    cube, the motors' gains (times PyBullet's defaults, POSITION_GAIN and VELOCITY_GAIN; the servo's kp and kd),
    the gripper's force, the command path's delay and calibration, and the speed limit, the motors' maxVelocity
    as in the course's call. "fixed" is the same motors and path at the physics' nominal point (`NOMINAL`, with
    `max_velocity_rad_s` the speed limit): the course's call, the gripper's force the STS3215's 3.35 N·m.

    `mode` is the display mode asked for (auto, gui, direct); `display_mode` the one it got.
    """

    kind: BodyName = "pybullet"

    def __init__(
        self,
        mode: str = "auto",
        time_step_s: float = 1.0 / 240.0,
        assets_dir: Path | str | None = None,
        link_damping: float | None = COURSE_LINK_DAMPING,
        max_velocity_rad_s: float = COURSE_MAX_VELOCITY_RAD_S,
        log: Callable[[str], None] = print,
        control_mode: str = "position",
        servo_damping_ratio: float = DEFAULT_DAMPING_RATIO,
        servo_natural_freq_rad_s: float = DEFAULT_NATURAL_FREQ_RAD_S,
        servo_torque_limit_nm: float = SERVO_TORQUE_LIMIT_NM,
        renders: bool = True,
        hull_collisions: bool = True,
        task: SceneTask | None = None,
        seed: int = 0,
        light_pictures: bool = False,  # the cameras' meshes (so101.bodies.camera_meshes); no shadows to leave out here
        physics: str = DEFAULT_PHYSICS,
        looks: str = DEFAULT_LOOKS,  # the window's: each layout's colours and light, as the pictures have them
    ):
        check_control_mode(control_mode)
        physics_ranges(physics)  # an unknown mode or a ranges file that makes no sense: refused in one line
        if not servo_torque_limit_nm > 0:
            raise ValueError(f"servo torque limit must be a positive number of N·m, got {servo_torque_limit_nm!r}")
        # Checks ζ and ωn before anything connects (the inertia here is a stand-in).
        pd_gains([1.0], servo_natural_freq_rad_s, servo_damping_ratio)
        self.control_mode = control_mode
        self.servo_damping_ratio = float(servo_damping_ratio)
        self.servo_natural_freq_rad_s = float(servo_natural_freq_rad_s)
        self.servo_torque_limit_nm = float(servo_torque_limit_nm)
        # Resolve the model first: a missing file must give our message, not PyBullet's.
        urdf = assets.urdf_path(None if assets_dir is None else Path(assets_dir))
        physics_urdf = pybullet_hulls.urdf_to_load(urdf, log) if hull_collisions else urdf
        self.display_mode, notice = resolve_mode(mode)
        if notice:
            log(notice)
        self.time_step_s = float(time_step_s)
        # The physics is always DIRECT: a GUI client would hold every step back to the
        # window's frame rate. GUI mode adds a window that mirrors the arm (so101.gui.viewer).
        cid: int = p.connect(p.DIRECT)
        if cid < 0:
            raise RuntimeError("PyBullet could not connect in DIRECT mode")
        # None once closed.
        self.client: int | None = cid
        self._window: Window | None = None
        self.renders = renders
        # Static plugins of every client, unloaded before anything loads (the renderer
        # cannot be loaded back). fileIOPlugin caches each file it opens, 15 MB of STL
        # here, for the client's lifetime; loading reads the files without it.
        for plugin in ("fileIOPlugin",) + (() if renders else ("tinyRendererPlugin",)):
            p.unloadPlugin(p.loadPlugin(plugin, physicsClientId=cid), physicsClientId=cid)
        p.setAdditionalSearchPath(pybullet_data.getDataPath(), physicsClientId=cid)
        p.setGravity(0, 0, -9.81, physicsClientId=cid)
        p.setPhysicsEngineParameter(fixedTimeStep=self.time_step_s, physicsClientId=cid)
        self.plane_id: int = p.loadURDF("plane.urdf", physicsClientId=cid)
        meshes = camera_meshes(urdf.parent, log) if renders and light_pictures else None
        self.robot_id: int = self._load_arm(physics_urdf, assets_dir, with_pads=task is not None, meshes=meshes)
        self.scene: TaskScene | None = None if task is None else task.pybullet_scene(cid, seed)
        if self.display_mode == "gui":
            self._window = Window(["so101.gui.viewer", "--urdf", str(urdf), *(["--task", task.name] if task else [])],
                                  on_showing=lambda: log(WINDOW_SHOWING),
                                  object_values=len(task.object_state_names) if task else 0, looks=looks, physics=physics)
        self.joints = [self._joint_info(i) for i in range(p.getNumJoints(self.robot_id, physicsClientId=cid))]
        self._indices = [joint.index for joint in ACTUATED_JOINTS]
        if link_damping is not None:
            # The course's setting, on the links it sets it on. Note: these are drag
            # coefficients on the links' Cartesian motion, not joint damping (docs/exercise-2.md).
            for index in range(len(self.joints)):
                p.changeDynamics(
                    self.robot_id, index, linearDamping=link_damping, angularDamping=link_damping,
                    physicsClientId=cid,
                )
        self.max_velocity_rad_s = float(max_velocity_rad_s)
        self.physics_mode = physics
        self._fixed_servos = replace(NOMINAL, speed_limit_deg_s=math.degrees(self.max_velocity_rad_s))
        # (joint index, goal in radians) pairs for the per-joint motor calls, while they are
        # still to be made; None once the motors have them.
        self._motor_goals: list[tuple[int, float]] | None = None
        self._goal_rad: FloatArray
        self._take_physics(None)  # varied physics' draw, or None: fixed, the servos `NOMINAL`
        self.steps = 0
        # The torques sent on the last step (servo mode; zeros in position mode).
        self.last_torques_nm: FloatArray = np.zeros(len(self._indices))
        if self.control_mode == "servo":
            # The default velocity motors would fight the torques: switch them off once.
            p.setJointMotorControlArray(
                self.robot_id, self._indices, p.VELOCITY_CONTROL,
                targetVelocities=[0.0] * len(self._indices), forces=[0.0] * len(self._indices),
                physicsClientId=cid,
            )
        self.layout_seed: int | None = None if task is None else seed  # the window draws its looks and cube
        if self.scene is not None and physics != DEFAULT_PHYSICS:
            self.reset_task(seed)
        elif physics != DEFAULT_PHYSICS:  # the arm alone (a replay): its servos and command path
            self._take_physics(physics_for(physics, seed))

    # -- set-up helpers --------------------------------------------------------------
    def _load_arm(self, physics_urdf: Path, assets_dir: Path | str | None, with_pads: bool,
                  meshes: dict[str, Path] | None) -> int:
        """The arm on its fixed base; `with_pads`, with the MJCF's jaw pads as extra collision boxes;
        with `meshes`, drawn with the cameras' meshes. Either loads from a copy of the URDF that names
        its meshes by absolute path."""
        options = dict(basePosition=[0, 0, 0], baseOrientation=[0, 0, 0, 1], useFixedBase=True, physicsClientId=self.client)
        if not with_pads and meshes is None:
            return int(p.loadURDF(str(physics_urdf), **options))
        text = physics_urdf.read_text(encoding="utf-8")
        if meshes is not None:
            text = urdf_for_cameras(text, physics_urdf.parent, meshes)
        if with_pads:
            pads = tuple(pad.grown() for pad in jaw_pads(assets.mjcf_path(None if assets_dir is None else Path(assets_dir))))
            rpy = {pad.name: tuple(p.getEulerFromQuaternion([*pad.quat_wxyz[1:], pad.quat_wxyz[0]])) for pad in pads}
            text = urdf_with_pads(text, physics_urdf.parent, pads, rpy)
        with tempfile.NamedTemporaryFile("w", suffix=".urdf", prefix="so101-arm-", encoding="utf-8") as copy:
            copy.write(text)
            copy.flush()
            robot_id = int(p.loadURDF(copy.name, **options))
        if not with_pads:
            return robot_id
        # Bullet's friction lets a held cube creep out of the jaws (measured: 13 mm down and sideways
        # in 4 s, then dropped); a friction anchor holds each contact where it started.
        for link in {GRIPPER_LINK_INDEX, GRIPPER.index}:
            p.changeDynamics(robot_id, link, frictionAnchor=1, physicsClientId=self.client)
        return robot_id

    def _joint_info(self, index: int) -> JointInfo:
        info = p.getJointInfo(self.robot_id, index, physicsClientId=self.client)
        return JointInfo(
            index=info[0], name=info[1].decode(), type=JOINT_TYPE_NAMES.get(info[2], str(info[2])),
            lower_rad=info[8], upper_rad=info[9], max_force=info[10], max_velocity=info[11],
        )

    def effective_inertias_kg_m2(self, angles_deg: Sequence[float] | None = None) -> FloatArray:
        """Each actuated joint's inertia about its own axis (the mass matrix diagonal) at a pose.

        It counts everything the joint carries (the outer links through their lever
        arms), so it depends on the outer joints' angles; default: the current pose.
        Note PyBullet loads this URDF without URDF_USE_INERTIA_FROM_FILE, so each link's
        own inertia comes from its collision shape; the masses are the URDF's.
        """
        angles_rad = np.radians(self.joint_angles_deg() if angles_deg is None else np.asarray(angles_deg, float))
        return self._inertias_at(angles_rad)

    def _inertias_at(self, angles_rad: FloatArray) -> FloatArray:
        mass_matrix = p.calculateMassMatrix(self.robot_id, angles_rad.tolist(), physicsClientId=self.client)
        return np.diag(np.asarray(mass_matrix, dtype=np.float64))

    @classmethod
    def from_settings(cls, settings: PyBulletSettings, node: NodeSettings, task: SceneTask | None = None,
                      log: Callable[[str], None] = print) -> "SO101Sim":
        """The simulation node's body: the course's motor or the servo, a window as `node` asks, no renderer
        (the node's pictures are drawn by so101.bodies.task_cameras), and the tick's step."""
        return cls(
            mode=node.display_mode, time_step_s=TICK_PERIOD_S, assets_dir=settings.assets_dir, log=log,
            control_mode=settings.control_mode, servo_damping_ratio=settings.servo_damping_ratio,
            renders=False,  # the node's pictures are so101.bodies.task_cameras'
            task=task, seed=node.seed, physics=node.physics, looks=node.looks,
        )

    # -- control ---------------------------------------------------------------------
    def start_targets_deg(self) -> tuple[float, ...]:
        """Home: the course's simulation starts there."""
        return HOME_POSE_DEG

    def set_targets_deg(self, targets_deg: Sequence[float]) -> None:
        """Goal angles in degrees for all six actuated joints (arm 0-4, gripper); with varied physics they
        go through its command path (its delay and calibration; the motors keep its speed limit)."""
        self._command.send(goal_deg(targets_deg), self.sim_time_s)
        self._take_goal()

    def set_time_step_s(self, time_step_s: float) -> None:
        """Change the physics step (before the first step: `sim_time_s` assumes one step size)."""
        if not time_step_s > 0:
            raise ValueError(f"time step must be a positive number of seconds, got {time_step_s!r}")
        self.time_step_s = float(time_step_s)
        p.setPhysicsEngineParameter(fixedTimeStep=self.time_step_s, physicsClientId=self.client)

    def targets_deg(self) -> FloatArray:
        return np.degrees(self._goal_rad)

    def reset_task(self, seed: int) -> None:
        """The task's scene laid out from `seed`, and the arm at home, still, its goal home."""
        if self.scene is None:
            raise ValueError("this simulation runs no task (start it with one: --task)")
        self._take_physics(physics_for(self.physics_mode, seed))
        self.scene.lay_out_seed(seed, self.physics)
        self.layout_seed = seed
        for joint_index, home_rad in zip(self._indices, np.radians(self._command.goal_deg).tolist()):
            p.resetJointState(self.robot_id, joint_index, home_rad, 0.0, physicsClientId=self.client)
        self.set_targets_deg(HOME_POSE_DEG)

    def step(self, count: int = 1) -> None:
        """Send new motor commands, if any, and advance the physics by `count` time steps."""
        client, robot_id = self.client, self.robot_id
        for _ in range(count):
            if not self._command.settled:  # a goal on its way (a delay)
                self._take_goal()
            if self.control_mode == "servo":
                # A servo gets the goal as a step, as a real one does over its bus; the
                # torque limit bounds its speed. (A goal slewed at 3 rad/s would hide the
                # lesson: a PD loop follows a ramp with little overshoot whatever ζ.)
                self._send_servo_torques()
            elif self._motor_goals is not None:
                # The course's own call, joint by joint: setJointMotorControlArray has no
                # maxVelocity, and PyBullet applies maxVelocity as a cap on the motor's
                # velocity target, so the joint is at 3 rad/s from the first step. The
                # course re-sends it every step; PyBullet keeps a motor's command until
                # it changes, so sending it once per goal moves the arm the same, step for
                # step (tests/test_course_motion.py), for less work per tick.
                servos = self._servos
                gains = dict(maxVelocity=math.radians(servos.speed_limit_deg_s),
                             positionGain=POSITION_GAIN * self._stiffness(servos),
                             velocityGain=VELOCITY_GAIN * servos.servo_damping, physicsClientId=client)
                for joint_index, goal_rad in self._motor_goals:
                    force = servos.gripper_torque_nm if joint_index == self._indices[-1] else MOTOR_FORCE_N_M
                    p.setJointMotorControl2(robot_id, joint_index, p.POSITION_CONTROL, targetPosition=goal_rad,
                                            force=force, **gains)
                self._motor_goals = None
            p.stepSimulation(physicsClientId=client)
            self.steps += 1
        if self._window is not None and self._window.due():
            states = p.getJointStates(robot_id, self._indices, physicsClientId=client)
            self._window.show([state[0] for state in states], None if self.scene is None else self.scene.object_state(),
                              self.layout_seed)

    @property
    def _servos(self) -> Physics:
        return self._fixed_servos if self.physics is None else self.physics

    def _stiffness(self, servos: Physics) -> float:
        """The motors' positionGain, times PyBullet's own: `servo_stiffness`, or what gives the physics' time
        constant. A position motor closes positionGain of the gap each step: its time constant is the step over
        the gain (40 ms at the node's 4 ms and 0.1), and it cannot close more than all of it."""
        if servos.servo_time_constant_s is None:
            return servos.servo_stiffness
        return min(1.0, self.time_step_s / servos.servo_time_constant_s) / POSITION_GAIN

    def _take_physics(self, physics: Physics | None) -> None:
        """The command path and motors as `physics` has them (None: fixed, the nominal servos): the motors get
        the new gains with their next goals."""
        self.physics = physics
        self._command = CommandPath(self._servos, HOME_POSE_DEG, slews=False)
        self._taken_deg = self._command.goal_deg
        self._goal_rad = np.radians(self._command.goal_deg)
        self._motor_goals = list(zip(self._indices, self._goal_rad.tolist()))

    def _take_goal(self) -> None:
        # The command path's goal now; the motors are told only of a new one (PyBullet keeps a motor's command).
        goal_deg = self._command.goal_at(self.sim_time_s, self.time_step_s)
        if goal_deg is not self._taken_deg:  # the path hands on each goal as it came (it does not slew here)
            self._taken_deg = goal_deg
            self._goal_rad = np.radians(goal_deg)
            self._motor_goals = list(zip(self._indices, self._goal_rad.tolist()))

    def _send_servo_torques(self) -> None:
        # PyBullet forgets TORQUE_CONTROL torques after each step: they are sent every step.
        states = p.getJointStates(self.robot_id, self._indices, physicsClientId=self.client)
        angles_rad = np.array([state[0] for state in states])
        velocities_rad_s = np.array([state[1] for state in states])
        zeros = [0.0] * len(self._indices)
        # With zero velocity and acceleration, inverse dynamics is the torque that holds the pose.
        gravity_nm = p.calculateInverseDynamics(
            self.robot_id, angles_rad.tolist(), zeros, zeros, physicsClientId=self.client,
        )
        kp, kd = pd_gains(self._inertias_at(angles_rad), self.servo_natural_freq_rad_s, self.servo_damping_ratio)
        limits_nm = np.full(len(self._indices), self.servo_torque_limit_nm)
        if self.physics is not None:
            kp, kd = kp * self.physics.servo_stiffness, kd * self.physics.servo_damping
            limits_nm[-1] = min(self.servo_torque_limit_nm, self.physics.gripper_torque_nm)
        self.last_torques_nm = pd_torque_nm(self._goal_rad - angles_rad, velocities_rad_s, kp, kd, gravity_nm, limits_nm)
        p.setJointMotorControlArray(
            self.robot_id, self._indices, p.TORQUE_CONTROL,
            forces=self.last_torques_nm.tolist(), physicsClientId=self.client,
        )

    # -- state -----------------------------------------------------------------------
    def joint_angles_deg(self) -> FloatArray:
        """Measured angles in degrees, arm joints 0-4 then the gripper (varied physics: as its calibration reports them)."""
        states = p.getJointStates(self.robot_id, self._indices, physicsClientId=self.client)
        return self._command.reported(np.degrees(np.array([state[0] for state in states], dtype=np.float64)))

    def joint_velocities_deg_s(self) -> FloatArray:
        states = p.getJointStates(self.robot_id, self._indices, physicsClientId=self.client)
        return np.degrees(np.array([state[1] for state in states], dtype=np.float64))

    @property
    def sim_time_s(self) -> float:
        return self.steps * self.time_step_s

    # -- pictures --------------------------------------------------------------------
    def show_pose_deg(self, angles_deg: Sequence[float]) -> None:
        """Put the joints at these six angles at once, without physics: a pose to draw (the camera node)."""
        for joint_index, angle_rad in zip(self._indices, np.radians(goal_deg(angles_deg)).tolist()):
            p.resetJointState(self.robot_id, joint_index, angle_rad, physicsClientId=self.client)

    def render_rgb(self, width: int = 640, height: int = 480, camera: Camera | WristCamera = DEFAULT_CAMERA) -> RgbImage:
        """The scene as an RGB image, uint8 of shape (height, width, 3), from `camera` (the orbiting
        one, or the one on the gripper).

        Uses the CPU renderer (ER_TINY_RENDERER), so it works in DIRECT mode with no
        display or GPU.
        """
        check_picture(self.renders, width, height)
        if isinstance(camera, WristCamera):
            if self.scene is None:  # as in MuJoCo, whose scene gets the camera with the task
                raise ValueError("the wrist camera is a task's: start the simulation with a task")
            state = p.getLinkState(self.robot_id, GRIPPER_LINK_INDEX, computeForwardKinematics=True,
                                   physicsClientId=self.client)
            origin = np.asarray(state[4])
            rotation = np.asarray(p.getMatrixFromQuaternion(state[5])).reshape(3, 3)
            view = p.computeViewMatrix(
                (origin + rotation @ camera.eye_m).tolist(), (origin + rotation @ camera.target_m).tolist(),
                (rotation @ camera.up).tolist(), physicsClientId=self.client)
        else:
            view = p.computeViewMatrixFromYawPitchRoll(
                cameraTargetPosition=list(camera.target_xyz_m), distance=camera.distance_m,
                yaw=camera.yaw_deg, pitch=camera.pitch_deg, roll=0.0, upAxisIndex=2,
                physicsClientId=self.client,
            )
        projection = p.computeProjectionMatrixFOV(
            fov=camera.fov_deg, aspect=width / height, nearVal=0.01, farVal=10.0, physicsClientId=self.client,
        )
        _, _, rgba, _, _ = p.getCameraImage(
            width, height, viewMatrix=view, projectionMatrix=projection,
            renderer=p.ER_TINY_RENDERER, physicsClientId=self.client,
        )
        return np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)[:, :, :3].copy()

    # -- life cycle ------------------------------------------------------------------
    def close(self) -> None:
        """Disconnect and close the window; safe to call twice."""
        if self._window is not None:
            self._window.close()
            self._window = None
        if self.client is not None and self.client >= 0:
            try:
                p.disconnect(physicsClientId=self.client)
            except p.error:
                pass  # already gone, e.g. the GUI window was closed
        self.client = None

    def __enter__(self) -> "SO101Sim":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
