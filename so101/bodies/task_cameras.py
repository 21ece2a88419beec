"""A task's two cameras, drawn by one renderer whatever body simulates the physics.

The front and the wrist pictures of a task's episodes (`so101 demos` and `so101 eval` in lockstep,
the camera node at the prompt) are drawn by MuJoCo's renderer (EGL: a GPU where there is one,
Mesa's software renderer otherwise) from the six joint angles and the task's object_state, on a
model made for drawing only: the MJCF's arm with the cameras' decimated meshes
(so101.bodies.camera_meshes) and the task's objects (its hooks), without shadows, reflections or
multisampling. PyBullet's arm and MuJoCo's are drawn alike, so the same state gives the same
picture on both: a policy that sees meets one look, whichever simulator made its demonstrations.
The physics stays each body's own.
"""

from __future__ import annotations

import ctypes
import os
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import numpy.typing as npt

from so101.bodies.backdrop import backdrop_picture, placement_for
from so101.bodies.backdrop_pool import with_unseen_pool
from so101.bodies.camera import DEFAULT_CAMERA, WRIST_CAMERA, WRIST_CAMERA_NAME, Camera, WristCamera, wrist_placement
from so101.bodies.camera_file import CameraFile
from so101.bodies.episode_cameras import drawn_front, fixed_cameras
from so101.bodies.looks import DEFAULT_LOOKS, Looks, looks_for
from so101.bodies.physics import DEFAULT_PHYSICS, Physics, physics_for
from so101.bodies.protocol import AnglesDeg, ObjectState, RgbImage, SceneTask
from so101.bodies.settings import NodeSettings
from so101.robot import ACTUATED_JOINTS

IMAGE_SIZE = (320, 240)  # the body node's `image` output (SO101_IMAGE_HZ)


def opengl_renderer() -> str | None:
    """GL_RENDERER of the OpenGL context current in this thread (the renderer's, after it drew), or None."""
    for library in ("libOpenGL.so.0", "libGL.so.1"):
        try:
            gl = ctypes.CDLL(library)
        except OSError:
            continue
        gl.glGetString.restype = ctypes.c_char_p
        gl.glGetString.argtypes = [ctypes.c_uint]
        name = gl.glGetString(0x1F01)  # GL_RENDERER
        return name.decode(errors="replace") if name else None
    return None


def mujoco_drawn_by() -> str:
    """MuJoCo's version, its OpenGL back end and the device of the context current in this thread."""
    import mujoco

    return f"MuJoCo {mujoco.__version__}, {os.environ.get('MUJOCO_GL', 'glfw').upper()}: {opengl_renderer() or 'unknown'}"


class ModelLooks:
    """What looks change in a MuJoCo model of a task's scene (its light, its floor's and its objects' colours),
    and the model's own, which fixed looks put back: the renderer's model, and MuJoCo's window's."""

    def __init__(self, model: Any) -> None:
        arm_root = int(model.body_rootid[model.joint(ACTUATED_JOINTS[0].name).bodyid[0]])
        self.object_roots = sorted({int(root) for root in model.body_rootid[1:]} - {arm_root})  # in the model's order
        self.object_geoms = [[geom for geom in range(model.ngeom) if int(model.body_rootid[model.geom_bodyid[geom]]) == root]
                             for root in self.object_roots]
        self.floor_geom = int(model.geom("floor").id)
        self.arm_root = arm_root
        self._own = (model.light_dir.copy(), model.light_diffuse.copy(), model.geom_rgba.copy())

    def show(self, model: Any, looks: Looks | None) -> None:
        """`looks` on `model` (None: the model's own)."""
        model.light_dir[:], model.light_diffuse[:], model.geom_rgba[:] = self._own
        if looks is not None:
            model.light_dir[:] = looks.light_dir
            model.light_diffuse[:] = looks.light_diffuse
            model.geom_rgba[self.floor_geom] = looks.floor_rgba
            for geoms, rgba in zip(self.object_geoms, looks.object_rgbas):
                model.geom_rgba[geoms] = rgba


class TaskCameras:
    """`draw(angles_deg, object_state, width, height)`: the front picture, and with a task the wrist's.

    `looks` "varied": `show_seed(seed)` gives the pictures that episode's looks (so101.bodies.looks);
    "fixed": the pictures as they always were, whatever the seed. `physics` "varied" (or a ranges file):
    `show_seed(seed)` draws that episode's cube, and the arm where it truly is when its calibration
    reports `angles_deg` (so101.bodies.physics), as the body it draws has them. `backdrops` (a camera's
    name to a photo, or a folder of them: so101.bodies.backdrop): that episode's photo where the floor
    and the sky would be; unseen looks draw the front camera's from the held-out pool where none is given."""

    def __init__(self, task: SceneTask | None, assets_dir: Path | str | None = None,
                 log: Callable[[str], None] = print, looks: str = DEFAULT_LOOKS,
                 poses: dict[str, CameraFile] | None = None, physics: str = DEFAULT_PHYSICS,
                 backdrops: dict[str, str] | None = None):
        # MuJoCo's body as a model to draw: posed by hand, never stepped.
        from so101.bodies.mujoco_sim import SO101MuJoCo

        looks_for(looks, 0)  # an unknown mode is refused here, in one line
        physics_for(physics, 0)
        self.task = task
        self.physics_mode = physics
        self.physics: Physics | None = None
        self.looks_mode = looks
        self.looks: Looks | None = None
        self.backdrops = with_unseen_pool(looks, dict(backdrops or {}))
        self.placements = {name: placement_for(path, 0, looks != DEFAULT_LOOKS) for name, path in self.backdrops.items()}
        # Light pictures whatever the task: one look, defined once, and a picture in milliseconds.
        self._model = SO101MuJoCo(mode="direct", assets_dir=assets_dir, log=log, renders=True, task=task,
                                  light_pictures=True)
        model = self._model.model
        # What the looks change, as the model has it: the fixed looks put these back.
        self._model_looks = ModelLooks(model)
        arm_root = self._model_looks.arm_root
        geom_roots = [int(model.body_rootid[model.geom_bodyid[geom]]) for geom in range(model.ngeom)]
        self._arm_geoms = np.array([root == arm_root for root in geom_roots])
        # The objects that can move (a joint of their own: the cube), not those fixed to the floor (the box).
        loose = {root for root in self._model_looks.object_roots if model.body_jntnum[root] > 0}
        self._loose_geoms = np.array([root in loose for root in geom_roots])
        self._wrist = int(model.camera(WRIST_CAMERA_NAME).id) if task is not None else None
        # A task's front camera frames its workspace, where `poses` (camera files) put it or where the
        # simulator's own stands; without a task, the whole arm (so101 snapshot's view).
        self.poses = dict(poses or {})
        front, wrist = fixed_cameras(self.poses)
        self.fixed_front = front if task is not None else DEFAULT_CAMERA
        if task is not None:
            model.vis.global_.fovy = front.fov_deg
        if self._wrist is not None and "wrist" in self.poses:
            pos, quat = wrist_placement(wrist)
            model.cam_pos[self._wrist], model.cam_quat[self._wrist], model.cam_fovy[self._wrist] = pos, quat, wrist.fov_deg
        self._fixed = (float(model.vis.global_.fovy), model.cam_pos.copy(), model.cam_fovy.copy())

    def show_seed(self, seed: int) -> None:
        """The looks and physics of episode seed `seed` from now on (varied ones; fixed ones stay as they are)."""
        if self.physics_mode != DEFAULT_PHYSICS:
            self.show_physics(physics_for(self.physics_mode, seed))
        self.placements = {name: placement_for(path, seed, self.looks_mode != DEFAULT_LOOKS)
                            for name, path in self.backdrops.items()}
        looks = looks_for(self.looks_mode, seed, len(self._model_looks.object_geoms))
        if looks == self.looks:
            return
        model = self._model.model
        fovy, cam_pos, cam_fovy = self._fixed
        model.vis.global_.fovy, model.cam_pos[:], model.cam_fovy[:] = fovy, cam_pos, cam_fovy
        self._model_looks.show(model, looks)
        if looks is not None:
            model.vis.global_.fovy = fovy + looks.front_fov_deg
            if self._wrist is not None:
                model.cam_pos[self._wrist] = cam_pos[self._wrist] + looks.wrist_shift_m
                model.cam_fovy[self._wrist] = cam_fovy[self._wrist] + looks.wrist_fov_deg
        self.looks = looks

    def show_physics(self, physics: Physics | None) -> None:
        """Draw with `physics` from now on (an episode's, as its dataset keeps it; None: fixed): its cube's
        size, and the arm where it truly is when its calibration reports the angles given to `draw`.
        The same physics again changes nothing (the eyes' pictures ask once a picture)."""
        if physics == self.physics:
            return
        self.physics = physics
        if self._model.scene is not None:
            self._model.scene.lay_out_seed(physics.seed if physics is not None else 0, physics)

    def front_camera(self) -> Camera:
        """The front camera as this episode's looks place it."""
        return drawn_front(self.fixed_front, self.looks)

    def draw(self, angles_deg: AnglesDeg | Sequence[float], object_state: ObjectState | Sequence[float], width: int,
             height: int, wrist: bool = True, front: Camera | None = None) -> tuple[RgbImage, RgbImage | None]:
        """(front, wrist) of the arm at the six `angles_deg` and the task's objects where `object_state`
        puts them (none yet: where they were); wrist None without a task, or not asked for. `front`: the
        front picture drawn from there, as it is (the looks' colours and light, not their camera's jitter)."""
        scene = self._model.scene
        if scene is not None and len(object_state):
            scene.show_object_state([float(value) for value in object_state])
        # After the objects: posing recomputes the kinematics of both.
        self._show_pose(angles_deg)
        front_camera = front or self.front_camera()
        if scene is not None:  # MuJoCo's free camera takes its field of view from the model
            self._model.model.vis.global_.fovy = front_camera.fov_deg
        picture = self._behind("front", self._model.render_rgb(width, height, front_camera), front_camera)
        if not (wrist and scene is not None):
            return picture, None
        return picture, self._behind("wrist", self._model.render_rgb(width, height, WRIST_CAMERA), WRIST_CAMERA)

    def _behind(self, name: str, picture: RgbImage, camera: Camera | WristCamera) -> RgbImage:
        """`picture` with camera `name`'s backdrop where it shows the floor or nothing (none: as it is)."""
        placement = self.placements.get(name)
        if placement is None:
            return picture
        height, width = picture.shape[:2]
        geoms = self._model.render_geoms(width, height, camera)
        behind = (geoms < 0) | (geoms == self._model_looks.floor_geom)
        return np.where(behind[:, :, None], backdrop_picture(placement, width, height), picture).astype(np.uint8)

    def arm_mask(self, angles_deg: AnglesDeg | Sequence[float], camera: Camera, width: int, height: int,
                 object_state: ObjectState | Sequence[float] = ()) -> npt.NDArray[np.bool_]:
        """The pixels that show the arm at the six `angles_deg` (and, given an `object_state`, the task's
        objects that move: the cube, not the box), seen from `camera` (its field of view its own): what
        moves in a task's pictures, which a camera's fit compares with a picture's."""
        scene = self._model.scene
        shown = self._arm_geoms
        if scene is not None and len(object_state):
            scene.show_object_state([float(value) for value in object_state])
            shown = self._arm_geoms | self._loose_geoms
        self._show_pose(angles_deg)
        self._model.model.vis.global_.fovy = camera.fov_deg
        try:
            geoms = self._model.render_geoms(width, height, camera)
        finally:
            self._model.model.vis.global_.fovy = self.front_camera().fov_deg
        mask: npt.NDArray[np.bool_] = shown[np.clip(geoms, 0, None)] & (geoms >= 0)
        return mask

    def _show_pose(self, angles_deg: AnglesDeg | Sequence[float]) -> None:
        """The arm where it is when it reports `angles_deg` (varied physics: its calibration's offsets taken off)."""
        angles = [float(angle) for angle in angles_deg]
        self._model.show_pose_deg(angles if self.physics is None else self.physics.true_deg(angles))

    def close(self) -> None:
        self._model.close()

    def __enter__(self) -> "TaskCameras":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def node_cameras(task: SceneTask | None, settings: NodeSettings, assets_dir: Path | str | None = None,
                 log: Callable[[str], None] = print) -> TaskCameras | None:
    """The cameras of a body node that publishes pictures (its `image` output, SO101_IMAGE_HZ, or its
    lockstep frames', SO101_LOCKSTEP_PICTURES), else None; one picture is drawn now, so a renderer that
    cannot work stops the node in one line before it joins."""
    if settings.lockstep_pictures is None and not settings.image_hz > 0:
        return None
    scenario = settings.scenario
    cameras = TaskCameras(task, assets_dir, log, scenario.looks, scenario.camera_poses, scenario.physics, scenario.backdrops)
    cameras.show_seed(settings.seed)
    from so101.robot import HOME_POSE_DEG

    cameras.draw(HOME_POSE_DEG, [], *(settings.lockstep_pictures or IMAGE_SIZE))
    return cameras
