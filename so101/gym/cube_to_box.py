"""`CubeToBoxEnv`: the cube_to_box task as a Gymnasium environment, its physics in this process.

One `step` is one lockstep frame of `so101 eval` and `so101 demos` (so101/runtime/lockstep.py): the
action's six joint targets go to the body (held within the joints' limits, as the body node holds a
joint_cmd's), the body steps 1/25 s (ten 4 ms steps), and the frame after is observed and judged
by the task's one success function. `reset(seed=N)` lays out the task's layout N and homes the arm, as
`so101 eval --seed N`'s episode does; a reset without a seed draws the layout's from the
environment's own generator (Gymnasium's `np_random`), so a seeded environment stays reproducible.
The body is the same class the dataflow's body node drives (so101.bodies), without a dataflow: a
vector environment of N processes runs N episodes at once. The pictures are drawn by the same one
renderer for both bodies (so101.bodies.task_cameras), made only where pictures are asked for.
"""

from __future__ import annotations

import logging
from typing import Any

import gymnasium
import numpy as np
import numpy.typing as npt

from so101.bodies.protocol import Body, ObjectState, RgbImage, TaskScene
from so101.bodies.registry import BODIES
from so101.bodies.task_cameras import TaskCameras
from so101.gym.spaces import (
    DEFAULT_CAMERA_SIZE, action_space, agent_pos, check_backdrop, check_body, check_camera_pose, check_camera_size, check_looks, check_obs_type, check_physics,
    check_render_mode, clamped_targets_deg, observation_space, observes_objects, sees, step_outcome,
)
from so101.runtime.dataflow import TICK_PERIOD_S
from so101.runtime.lockstep import DEFAULT_LOCKSTEP_FPS, steps_per_frame
from so101.tasks import CUBE_TO_BOX

logger = logging.getLogger(__name__)
# Layouts drawn for a reset without a seed: any seed so101 eval takes.
MAX_DRAWN_SEED = 2**31


class CubeToBoxEnv(gymnasium.Env[dict[str, Any], npt.NDArray[Any]]):
    """The SO-101 putting a cube into a box, on PyBullet or MuJoCo (`body`).

    Action: six joint targets, degrees and the gripper 0-100. Observation: `agent_pos` (the six
    angles, those units); `environment_state` (the task's ten object values) for obs_type `state`
    and `all`; `pixels` (`front`, `wrist`: HxWx3 uint8 at `camera_size`, (width, height)) for
    `pixels_agent_pos` and `all`. `looks` "varied" draws each layout's light, colours and camera
    placement from its seed (so101.bodies.looks); `camera_pose` ({"front": FILE}, or "front=FILE") draws
    a camera from where a camera file puts it (so101.bodies.camera_file); `backdrop` ({"front": IMAGE}, or
    "front=IMAGE") a photo of a workspace behind a camera's scene (so101.bodies.backdrop). `physics` "varied" (or a ranges file)
    draws each layout's physics from its seed (so101.bodies.physics): `agent_pos` is then as the arm's
    calibration reports it. info["is_success"]: the task's success function."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": DEFAULT_LOCKSTEP_FPS}

    def __init__(self, body: str = "pybullet", obs_type: str = "state",
                 camera_size: tuple[int, int] = DEFAULT_CAMERA_SIZE, looks: str = "fixed", camera_pose: object = None,
                 render_mode: str | None = "rgb_array", assets_dir: str | None = None, physics: str = "fixed",
                 backdrop: object = None):
        # Every argument checked before a simulator loads: a bad one is one line.
        self.body_name, self.obs_type = check_body(body), check_obs_type(obs_type)
        self.camera_size, self.looks = check_camera_size(camera_size), check_looks(looks)
        self.camera_poses = check_camera_pose(camera_pose)
        self.backdrops = check_backdrop(backdrop)
        self.physics = check_physics(physics)
        self.render_mode = check_render_mode(render_mode)
        # What LeRobot's rollout hands a policy that reads language (its `task`).
        self.task = self.task_description = CUBE_TO_BOX.instruction
        self.action_space = action_space()
        self.observation_space = observation_space(self.obs_type, self.camera_size, CUBE_TO_BOX.object_state_names)
        self._assets_dir = assets_dir
        self._body: Body = BODIES[self.body_name].body_class()(
            mode="direct", time_step_s=TICK_PERIOD_S, assets_dir=assets_dir, renders=False, log=logger.info,
            task=CUBE_TO_BOX, seed=0, physics=self.physics)
        scene = self._body.scene
        assert scene is not None  # made with a task
        self._scene: TaskScene = scene
        self._frame_steps = steps_per_frame(DEFAULT_LOCKSTEP_FPS, TICK_PERIOD_S)
        self.layout_seed = 0  # the layout of the episode running
        self.episode = 0  # resets so far
        self.frame = 0  # frames stepped since the reset
        self._cameras: TaskCameras | None = self._make_cameras() if sees(self.obs_type) else None
        self._drawn: tuple[int, int, RgbImage, RgbImage | None] | None = None  # (episode, frame, front, wrist)

    # -- what the expert and the tests read of the state now
    def joint_angles_deg(self) -> npt.NDArray[np.float64]:
        """The arm's six measured angles, in the body's degrees (the gripper's too)."""
        return np.asarray(self._body.joint_angles_deg(), dtype=np.float64)

    def object_state(self) -> ObjectState:
        """The task's objects now (cube_to_box's OBJECT_STATE_NAMES order): the cube's pose, the box's place."""
        return self._scene.object_state()

    # -- Gymnasium
    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[dict[str, Any], dict[str, Any]]:
        super().reset(seed=seed)
        self.layout_seed = int(seed) if seed is not None else int(self.np_random.integers(0, MAX_DRAWN_SEED))
        self._body.reset_task(self.layout_seed)
        if self._cameras is not None:
            self._cameras.show_seed(self.layout_seed)
        self.episode += 1
        self.frame = 0
        return self._observation(), self._info(self._scene.succeeded())

    def step(self, action: npt.NDArray[Any]) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        if self.episode == 0:
            raise gymnasium.error.ResetNeeded("call reset before step")
        self._body.set_targets_deg(clamped_targets_deg(action))
        self._body.step(self._frame_steps)
        self.frame += 1
        success = self._scene.succeeded()
        reward, terminated = step_outcome(CUBE_TO_BOX, success)
        return self._observation(), reward, terminated, False, self._info(success)

    def render(self) -> RgbImage | None:  # type: ignore[override]
        """The front camera's picture now, at camera_size (render_mode "rgb_array"); None without a render mode."""
        if self.render_mode is None:
            return None
        return self._pictures(wrist=False)[0]

    def close(self) -> None:
        self._body.close()
        if self._cameras is not None:
            self._cameras.close()
            self._cameras = None

    # -- the parts
    def _make_cameras(self) -> TaskCameras:
        cameras = TaskCameras(CUBE_TO_BOX, self._assets_dir, log=logger.info, looks=self.looks, poses=self.camera_poses,
                              physics=self.physics, backdrops=self.backdrops)
        cameras.show_seed(self.layout_seed)
        return cameras

    def _pictures(self, wrist: bool) -> tuple[RgbImage, RgbImage | None]:
        """The front picture (and the wrist's) of the frame now, drawn once a frame."""
        drawn = self._drawn
        if drawn is None or drawn[:2] != (self.episode, self.frame) or (wrist and drawn[3] is None):
            if self._cameras is None:  # render() of an environment without pictures: the renderer is made now
                self._cameras = self._make_cameras()
            front, wrist_picture = self._cameras.draw(self.joint_angles_deg(), self.object_state(), *self.camera_size,
                                                      wrist=wrist)
            drawn = self._drawn = (self.episode, self.frame, front, wrist_picture)
        return drawn[2], drawn[3]

    def _observation(self) -> dict[str, Any]:
        observation: dict[str, Any] = {"agent_pos": agent_pos(self.joint_angles_deg().tolist())}
        if observes_objects(self.obs_type):
            observation["environment_state"] = np.asarray(self.object_state(), dtype=np.float32)
        if sees(self.obs_type):
            front, wrist = self._pictures(wrist=True)
            observation["pixels"] = {"front": front, "wrist": wrist}
        return observation

    def _info(self, success: bool) -> dict[str, Any]:
        return {"is_success": bool(success), "seed": self.layout_seed, "frame": self.frame}
