"""MuJoCo's window, in a process of its own that mirrors the arm's joint angles.

The same rule as the PyBullet window (so101/gui/viewer.py, whose shared slots and priority
this uses): the physics runs headless in the node, and this process, at the lowest CPU
priority, shows the latest angles in MuJoCo's own viewer (`mujoco.viewer`: drag to turn,
right drag to move, wheel to zoom), never stepping the physics itself. Each layout is drawn as the
pictures draw it: its cube at its size (`--physics`), and with `--looks varied` (or unseen) its light
and its colours (so101.bodies.task_cameras.ModelLooks, the renderer's own).

    python -m so101.gui.mujoco_viewer --shared FILE --mjcf MJCF [--fps N] [--task NAME] [--looks L] [--physics P]
    (started by `Window`, not by hand)
"""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path

from so101.robot import ACTUATED_JOINTS
from so101.bodies.looks import DEFAULT_LOOKS, looks_for
from so101.bodies.physics import DEFAULT_PHYSICS, physics_for
from so101.bodies.window import ANGLES, FRAME, LAYOUT, OBJECTS, OPEN, SHOWING, STATUS, shared_array
from so101.gui.viewer import lowest_priority, viewer_main


def run_viewer(shared_path: Path, mjcf: Path, fps: float, task_name: str = "", looks: str = DEFAULT_LOOKS,
               physics: str = DEFAULT_PHYSICS) -> int:
    import mujoco
    import mujoco.viewer

    from so101.bodies.mujoco_model import collision_hulls, scene_model
    from so101.bodies.task_cameras import ModelLooks
    from so101.tasks import task_named

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the process group: the physics closes this
    lowest_priority()
    parent = os.getppid()
    mapping, shared = shared_array(shared_path)
    task = task_named(task_name) if task_name else None
    model = scene_model(mjcf, collision_hulls(mjcf), task=task)  # the node's scene, with the visual meshes
    data = mujoco.MjData(model)
    scene = task.mujoco_scene(model, data, 0) if task is not None else None
    model_looks = ModelLooks(model) if scene is not None else None
    shown_layout = -1.0
    qpos = [int(model.joint(joint.name).qposadr[0]) for joint in ACTUATED_JOINTS]
    frame_period_s = 1.0 / fps
    shown_frame = -1.0
    try:
        with mujoco.viewer.launch_passive(model, data, show_left_ui=False, show_right_ui=False) as viewer:
            shared[STATUS] = OPEN
            viewer.cam.lookat[:] = (0.1, 0.0, 0.15)
            viewer.cam.distance, viewer.cam.azimuth, viewer.cam.elevation = 0.7, 135.0, -25.0
            shared[STATUS] = SHOWING
            # Ends with the physics (its close() terminates this process, or the parent changes) or the window.
            while viewer.is_running() and os.getppid() == parent:
                frame = shared[FRAME]
                if frame != shown_frame:
                    shown_frame = frame
                    with viewer.lock():
                        data.qpos[qpos] = shared[ANGLES:OBJECTS]
                        if scene is not None and model_looks is not None:
                            if shared[LAYOUT] != shown_layout and shared[LAYOUT] >= 0:  # a new layout: its cube, its looks
                                shown_layout = float(shared[LAYOUT])
                                seed = int(shown_layout)
                                scene.lay_out_seed(seed, physics_for(physics, seed))
                                model_looks.show(model, looks_for(looks, seed, len(model_looks.object_geoms)))
                            scene.show_object_state(shared[OBJECTS:].tolist())
                        mujoco.mj_kinematics(model, data)
                    viewer.sync()
                time.sleep(frame_period_s)
    finally:
        del shared  # the view first: a mapping with a view on it cannot close
        mapping.close()
    return 0


def main(argv: list[str] | None = None) -> int:
    return viewer_main(argv, "so101.gui.mujoco_viewer", __doc__.splitlines()[0], "mjcf", run_viewer)


if __name__ == "__main__":
    sys.exit(main())
