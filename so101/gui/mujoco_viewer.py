"""MuJoCo's window, in a process of its own that mirrors the arm's joint angles.

The same rule as the PyBullet window (so101/gui/viewer.py, whose shared slots and priority
this uses): the physics runs headless in the node, and this process, at the lowest CPU
priority, shows the latest angles in MuJoCo's own viewer (`mujoco.viewer`: drag to turn,
right drag to move, wheel to zoom), never stepping the physics itself.

    python -m so101.gui.mujoco_viewer --shared FILE --mjcf MJCF [--fps N]    (started by `Window`, not by hand)
"""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path

from so101.robot import ACTUATED_JOINTS
from so101.bodies.window import ANGLES, FRAME, OBJECTS, OPEN, SHOWING, STATUS, shared_array
from so101.gui.viewer import lowest_priority, viewer_main


def run_viewer(shared_path: Path, mjcf: Path, fps: float, task_name: str = "") -> int:
    import mujoco
    import mujoco.viewer

    from so101.bodies.mujoco_model import collision_hulls, scene_model
    from so101.tasks import task_named

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the process group: the physics closes this
    lowest_priority()
    parent = os.getppid()
    mapping, shared = shared_array(shared_path)
    task = task_named(task_name) if task_name else None
    model = scene_model(mjcf, collision_hulls(mjcf), task=task)  # the node's scene, with the visual meshes
    data = mujoco.MjData(model)
    scene = task.mujoco_scene(model, data, 0) if task is not None else None
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
                        if scene is not None:
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
