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
from typing import Callable, Sequence

from so101.bodies.camera import DEFAULT_CAMERA, WRIST_CAMERA
from so101.bodies.protocol import AnglesDeg, ObjectState, RgbImage, SceneTask
from so101.bodies.settings import NodeSettings


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


class TaskCameras:
    """`draw(angles_deg, object_state, width, height)`: the front picture, and with a task the wrist's."""

    renderer = "MuJoCo"

    def __init__(self, task: SceneTask | None, assets_dir: Path | str | None = None,
                 log: Callable[[str], None] = print):
        # MuJoCo's body as a model to draw: posed by hand, never stepped.
        from so101.bodies.mujoco_sim import SO101MuJoCo

        self.task = task
        self._model = SO101MuJoCo(mode="direct", assets_dir=assets_dir, log=log, renders=True, task=task,
                                  light_pictures=task is not None)

    def draw(self, angles_deg: AnglesDeg | Sequence[float], object_state: ObjectState | Sequence[float], width: int,
             height: int) -> tuple[RgbImage, RgbImage | None]:
        """(front, wrist) of the arm at the six `angles_deg` and the task's objects where `object_state`
        puts them (none yet: where they were); wrist None without a task."""
        scene = self._model.scene
        if scene is not None and len(object_state):
            scene.show_object_state([float(value) for value in object_state])
        self._model.show_pose_deg([float(angle) for angle in angles_deg])  # after the objects: it recomputes the kinematics of both
        front = self._model.render_rgb(width, height, DEFAULT_CAMERA)
        wrist = self._model.render_rgb(width, height, WRIST_CAMERA) if scene is not None else None
        return front, wrist

    def drawn_by(self) -> str:
        """Who draws, in words: MuJoCo's version, its OpenGL back end and the device OpenGL names (a GPU,
        or Mesa's llvmpipe in software), read after a picture was drawn; "" before."""
        return mujoco_drawn_by() if self._model.has_drawn() else ""

    def close(self) -> None:
        self._model.close()

    def __enter__(self) -> "TaskCameras":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def lockstep_cameras(task: SceneTask | None, settings: NodeSettings, assets_dir: Path | str | None = None,
                     log: Callable[[str], None] = print) -> TaskCameras | None:
    """The cameras of a body node whose lockstep frames carry pictures (SO101_LOCKSTEP_PICTURES), else None;
    one picture is drawn now, so a renderer that cannot work stops the node in one line before it joins."""
    if settings.lockstep_pictures is None:
        return None
    cameras = TaskCameras(task, assets_dir, log)
    from so101.robot import HOME_POSE_DEG

    cameras.draw(HOME_POSE_DEG, [], *settings.lockstep_pictures)
    return cameras
