"""The arm in a browser: a viser server showing the URDF's meshes, posed by the joint angles it is given.

One frame per joint, nested as the URDF's tree (so101/web/urdf_scene.py), so a new pose is one
rotation per joint sent to every open page, and each browser works out the rest. The page has
viser's own orbit (drag), pan (right drag) and zoom (wheel); a panel with the joint angles as
text, a rolling plot of the last seconds, the body's camera picture when it has one, and a
marker while an episode records. viser serves its page from its installed package and the
meshes from the model files: nothing comes from the internet. Read-only: the page has no
control that sends anything to the arm.

A task's objects are drawn as the pictures draw each layout (`layout_look`): the cube at the size its
physics gives it and, under varied or unseen looks, the floor's and objects' colours and the light's
direction and strength. A backdrop is a photo behind one camera's view, and stays out of a page
seen from anywhere.
"""

from __future__ import annotations

import html
import logging
import time
from collections import deque
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import numpy.typing as npt
import trimesh
import viser
from viser import uplot

from so101.bodies.looks import LIGHT_DIFFUSE, Looks
from so101.bodies.physics import Physics
from so101.robot import ACTUATED_JOINTS
from so101.tasks.cube_to_box import CubeToBox
from so101.web.urdf_scene import UrdfScene

# The rolling plot: this many seconds, one point per pose shown, redrawn this often.
PLOT_SECONDS = 10.0
PLOT_HZ = 10.0
# A joint that moved less than this since the pages last drew it is not sent again (far below a pixel).
MOVED_DEG = 0.01
ANGLE_TEXT_TITLE = "**Joint angles**"
# The plot's line colours, one per joint.
PLOT_COLOURS = ("#e6194b", "#3cb44b", "#4363d8", "#f58231", "#911eb4", "#42d4f4")
CAMERA_POSITION = (0.55, -0.45, 0.40)
CAMERA_LOOK_AT = (0.10, 0.0, 0.15)
# A task's object that moved less than this since the pages last drew it is not sent again.
MOVED_M = 0.0002
# Under varied looks the page's own lights give way to one light as the looks draw it: at the middle of
# the looks' strengths as bright as the page's own main light (viser's 3.0), and from this far away.
LOOKS_LIGHT_INTENSITY = 3.0 / (sum(LIGHT_DIFFUSE) / 2)
LOOKS_LIGHT_DISTANCE_M = 2.0


def rgb255(rgba: Sequence[float]) -> tuple[int, int, int]:
    red, green, blue = (round(component * 255) for component in rgba[:3])
    return red, green, blue


@dataclass(frozen=True)
class LayoutLook:
    """What the page draws of one layout, as its pictures draw it."""

    cube_size_m: float
    cube_rgb: tuple[int, int, int]
    box_rgb: tuple[int, int, int]
    floor_rgb: tuple[int, int, int] | None  # None: the page's own see-through grid
    light_position: tuple[float, float, float] | None  # None: the page's own lights
    light_intensity: float


def layout_look(task: CubeToBox, looks: Looks | None, physics: Physics | None) -> LayoutLook:
    """A layout's look on the page: `looks` (None: fixed, the task's own colours and the page's lights)
    and `physics` (None: fixed, the task's cube) as so101.bodies.looks and .physics draw them for its seed."""
    cube_size_m = 2 * (task.cube.half_size_m if physics is None else physics.cube_half_size_m)
    if looks is None:
        return LayoutLook(cube_size_m, rgb255(task.cube.rgba), rgb255(task.box.rgba), None, None, 0.0)
    cube_rgba, box_rgba = looks.object_rgbas[:2]  # the task's objects in the model's order: the cube, the box
    # A directional light shines from where it stands towards the origin: it stands against its direction.
    position = tuple(-LOOKS_LIGHT_DISTANCE_M * part for part in looks.light_dir)
    return LayoutLook(cube_size_m, rgb255(cube_rgba), rgb255(box_rgba), rgb255(looks.floor_rgba),
                      (position[0], position[1], position[2]), LOOKS_LIGHT_INTENSITY * looks.light_diffuse)


def recording_html(recording: tuple[int, str] | None) -> str:
    """The marker shown while an episode records (empty when none does)."""
    if recording is None:
        return ""
    episode, task = recording
    return (f'<div style="color:#d01010;font-weight:bold">● recording episode {episode}'
            + (f": {html.escape(task)}" if task else "") + "</div>")


def angles_markdown(angles_deg: Sequence[float]) -> str:
    """The joint angles as the page shows them, one line per joint (a test reads them back)."""
    # + 0.0: a joint resting a hair below zero reads 0.0°, not -0.0°.
    rows = [f"{joint.name}: {round(angle, 1) + 0.0:.1f}°" for joint, angle in zip(ACTUATED_JOINTS, angles_deg)]
    return ANGLE_TEXT_TITLE + "\n\n" + "  \n".join(rows)


class WebView:
    """A viser server on host:port showing `scene`; `show(angles_deg)` poses the arm. `close()` is safe twice."""

    def __init__(self, scene: UrdfScene, host: str, port: int):
        # A connection closed before its first request (a browser's speculative one, a port scan) is
        # no failure of the view, but websockets logs it as an error with a traceback.
        logging.getLogger("websockets.server").setLevel(logging.CRITICAL)
        self.server: viser.ViserServer | None = viser.ViserServer(host=host, port=port, verbose=False)
        server = self.server
        server.scene.set_up_direction("+z")
        # No shadows: each shadow map draws the arm once more per frame, which a browser on software WebGL feels.
        server.scene.configure_default_lights(cast_shadow=False)
        # In front of the arm, a little to its right and above (metres, the URDF's frame: x forward, z up).
        server.initial_camera.position = CAMERA_POSITION
        server.initial_camera.look_at = CAMERA_LOOK_AT
        self._ground = server.scene.add_grid("/ground", width=0.6, height=0.6, cell_size=0.05)
        server.scene.add_frame(scene.link_path(scene.root_link), show_axes=False)
        self._joints = {joint.name: joint for joint in scene.joints}
        self._joint_frames = {}
        for joint in scene.joints:
            self._joint_frames[joint.name] = server.scene.add_frame(
                scene.link_path(joint.child), show_axes=False, position=joint.xyz, wxyz=joint.rotation(0.0))
        for number, visual in enumerate(scene.visuals):
            mesh = trimesh.load_mesh(visual.mesh_file)
            server.scene.add_mesh_simple(
                f"{scene.link_path(visual.link)}/visual_{number}", np.asarray(mesh.vertices, dtype=np.float32),
                np.asarray(mesh.faces, dtype=np.uint32), color=rgb255(visual.rgba), position=visual.xyz, wxyz=visual.wxyz)
        self._cube: viser.BoxHandle | None = None
        self._box: viser.FrameHandle | None = None
        self._plates: list[viser.BoxHandle] = []
        self._light: viser.DirectionalLightHandle | None = None
        self._look: LayoutLook | None = None
        self._shown_objects: npt.NDArray[np.float64] | None = None
        self._recording = server.gui.add_html("", visible=False)
        self._angles = server.gui.add_markdown(angles_markdown([0.0] * len(ACTUATED_JOINTS)))
        self._started = time.monotonic()
        self._history: deque[tuple[float, tuple[float, ...]]] = deque()
        self._plot = server.gui.add_uplot(
            data=self._plot_data(), title=f"the last {PLOT_SECONDS:g} s (degrees)", aspect=1.6,
            scales={"x": uplot.Scale(time=False)},
            series=(uplot.Series(label="s"), *(uplot.Series(label=joint.name, stroke=colour, width=1.5)
                                               for joint, colour in zip(ACTUATED_JOINTS, PLOT_COLOURS))),
        )
        self._picture: viser.GuiImageHandle | None = None
        self._shown_deg: dict[str, float] = {}  # each joint's angle as the pages show it
        self._plotted_at = -np.inf

    def _plot_data(self) -> tuple[npt.NDArray[np.float64], ...]:
        if not self._history:
            return (np.zeros(1),) + tuple(np.zeros(1) for _ in ACTUATED_JOINTS)
        times = np.array([t for t, _ in self._history])
        angles = np.array([a for _, a in self._history])
        return (times, *(angles[:, column] for column in range(angles.shape[1])))

    def show(self, angles_deg: Sequence[float]) -> None:
        """The arm posed at six angles in degrees (five arm joints, the gripper). Only what changed is
        sent: a still arm costs the pages nothing to draw, and the plot moves on PLOT_HZ times a second."""
        server = self.server
        if server is None:
            return
        now = time.monotonic() - self._started
        self._history.append((now, tuple(float(a) for a in angles_deg)))
        while self._history and self._history[0][0] < now - PLOT_SECONDS:
            self._history.popleft()
        text = angles_markdown(angles_deg)
        with server.atomic():
            for joint, angle in zip(ACTUATED_JOINTS, angles_deg):
                if abs(angle - self._shown_deg.get(joint.name, np.inf)) >= MOVED_DEG:
                    self._joint_frames[joint.name].wxyz = self._joints[joint.name].rotation(np.radians(angle))
                    self._shown_deg[joint.name] = angle
            if text != self._angles.content:
                self._angles.content = text
            if now - self._plotted_at >= 1.0 / PLOT_HZ:
                self._plot.data = self._plot_data()
                self._plotted_at = now

    def add_task(self, task: CubeToBox) -> None:
        """A task's cube and box on the floor, hidden until `show_objects` poses them."""
        if self.server is None:
            return
        scene = self.server.scene
        look = layout_look(task, None, None)  # the task's own, until a layout's look is shown
        self._box = scene.add_frame("/box", show_axes=False, visible=False)
        self._plates = [scene.add_box(f"/box/plate_{number}", color=look.box_rgb,
                                      dimensions=np.multiply(2, half_extents), position=centre)
                        for number, (centre, half_extents) in enumerate(task.box.plates())]
        self._cube = scene.add_box("/cube", color=look.cube_rgb, dimensions=(look.cube_size_m,) * 3, visible=False)
        self._look = look

    def show_layout(self, look: LayoutLook) -> None:
        """The task's objects (add_task's), floor and light in a layout's look; nothing is sent for the look shown."""
        server, cube = self.server, self._cube
        if server is None or cube is None or look == self._look:
            return
        with server.atomic():
            cube.dimensions, cube.color = (look.cube_size_m,) * 3, look.cube_rgb
            for plate in self._plates:
                plate.color = look.box_rgb
            self._ground.plane_color = look.floor_rgb or (255, 255, 255)
            self._ground.plane_opacity = 0.0 if look.floor_rgb is None else 1.0
            server.scene.configure_default_lights(enabled=look.light_position is None, cast_shadow=False)
            if look.light_position is not None:
                if self._light is None:
                    self._light = server.scene.add_light_directional("/looks_light", cast_shadow=False)
                self._light.position, self._light.intensity = look.light_position, look.light_intensity
            if self._light is not None:
                self._light.visible = look.light_position is not None
        self._look = look

    def show_objects(self, object_state: Sequence[float]) -> None:
        """The task's objects posed as an object_state has them (the cube's centre and x y z w quaternion,
        the box's position); only when they moved."""
        if self.server is None or self._cube is None or self._box is None:
            return
        state = np.asarray(object_state[:10], dtype=np.float64)
        if self._shown_objects is not None and np.all(np.abs(state - self._shown_objects) < MOVED_M):
            return
        x, y, z, qx, qy, qz, qw, box_x, box_y, box_z = state.tolist()
        with self.server.atomic():
            self._cube.position, self._cube.wxyz = (x, y, z), (qw, qx, qy, qz)
            self._box.position = (box_x, box_y, box_z)
            self._cube.visible = self._box.visible = True
        self._shown_objects = state

    def show_recording(self, recording: tuple[int, str] | None) -> None:
        """The recording marker at the panel's top: (episode, task) while one records, None to hide it."""
        if self.server is None:
            return
        self._recording.content = recording_html(recording)
        self._recording.visible = recording is not None

    def show_picture(self, rgb: npt.NDArray[np.uint8]) -> None:
        """The body's camera picture, under the plot (added on the first one)."""
        if self.server is None:
            return
        if self._picture is None:
            self._picture = self.server.gui.add_image(rgb, label="camera", format="jpeg")
        else:
            self._picture.image = rgb

    def close(self) -> None:
        server, self.server = self.server, None
        if server is not None:
            server.stop()

