"""The PyBullet window, in a process of its own that mirrors the arm's joint angles.

In PyBullet's GUI mode every API call waits for the window's render thread, so on a
machine with slow graphics (software OpenGL, a virtual machine, WSL) the physics runs
at the window's frame rate: 84 steps a second instead of 250 under Xvfb here. So the
physics always runs in its own DIRECT client, and the window is a second PyBullet
client, in another process (at the lowest priority once it shows the arm), that loads the
same arm, never steps it, and sets its joints to the latest angles at most `fps` times a second.
The window keeps PyBullet's own camera controls (Ctrl + left drag turns, the wheel
zooms, Ctrl + middle drag pans).

The two processes share one small file, mapped into both (so101/bodies/window.py, the physics'
side): a frame counter, the viewer's state, the six joint angles in radians
(so101.robot.ACTUATED_JOINTS order) and, with a task (`--task NAME`), its objects' poses
(so101.tasks' object_state), which this process shows with the task's own scene, and the seed of
the layout shown. Each layout is drawn as the pictures draw it: the cube at the size its physics
gives it (`--physics`), and with `--looks varied` (or unseen) the floor's and the objects' colours
and the light's direction drawn from its seed. PyBullet's window cannot dim or brighten its light,
and its camera is the person's (the mouse), not the front camera; fixed looks keep PyBullet's own
checkered floor, the course's.

    python -m so101.gui.viewer --shared FILE --urdf URDF [--fps N] [--task NAME] [--looks L] [--physics P]
    (started by `Window`, not by hand)
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np

from so101.bodies.looks import DEFAULT_LOOKS, LOOKS_CHOICES, looks_for
from so101.bodies.physics import DEFAULT_PHYSICS, physics_for
from so101.bodies.window import ANGLES, DEFAULT_FPS, FRAME, LAYOUT, OBJECTS, OPEN, SHOWING, STATUS, shared_array
from so101.robot import ACTUATED_JOINTS

# With the arm still and the mouse unused, the window is drawn this seldom; any
# movement brings back the full frame rate for BUSY_FOR_S.
IDLE_PERIOD_S = 0.25
BUSY_FOR_S = 1.0
# The viewer's niceness where SCHED_IDLE is not to be had.
VIEWER_NICENESS = 19
# The course's camera: where the window starts.
CAMERA = {"cameraDistance": 0.6, "cameraYaw": 45, "cameraPitch": -30, "cameraTargetPosition": [0, 0, 0.15]}


def process_threads() -> list[int]:
    """This process's threads (Linux); elsewhere 0, the calling thread."""
    try:
        return [int(thread) for thread in os.listdir("/proc/self/task")]
    except OSError:
        return [0]


def keep_to_one_cpu() -> None:
    """Every thread of this process, and the threads started later, keeps to the last CPU,
    leaving the others whole to the physics and dora (on 2 cores that cut the ticks dora
    dropped from about 5% to 1%). Linux only; elsewhere the scheduler decides."""
    if not hasattr(os, "sched_setaffinity"):
        return
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) < 2:
        return
    for thread in process_threads():
        with contextlib.suppress(ProcessLookupError):  # a thread that has just ended
            os.sched_setaffinity(thread, cpus[-1:])


def lowest_priority() -> None:
    """The window runs only on CPU time nothing else wants: PyBullet's GUI keeps a thread
    spinning (its MotionThreadFunc polls with usleep(0)) and draws in software where there
    is no GPU. On Linux on one CPU (keep_to_one_cpu), every thread of the process in the
    SCHED_IDLE class (PyBullet's and Mesa's start with the window, so each is set; threads
    started later inherit it); elsewhere the highest niceness."""
    keep_to_one_cpu()
    try:
        for thread in process_threads():
            with contextlib.suppress(ProcessLookupError):
                os.sched_setscheduler(thread, os.SCHED_IDLE, os.sched_param(0))
        return
    except (AttributeError, OSError):
        pass  # not Linux
    try:
        os.nice(VIEWER_NICENESS)
    except OSError:
        pass  # not allowed here: the same priority as the physics


def show_layout(scene, plane_id: int, client: int, seed: int, looks: str, physics: str) -> None:
    """The task's `scene` laid out as episode seed `seed`'s pictures show it: its cube at the size `physics`
    gives it, and `looks`' colours and light (fixed: the window's own)."""
    import pybullet as p

    scene.lay_out_seed(seed, physics_for(physics, seed))  # a cube of another size is a new body
    drawn = looks_for(looks, seed, len(scene.object_ids))
    if drawn is None:
        return
    p.changeVisualShape(plane_id, -1, rgbaColor=list(drawn.floor_rgba), textureUniqueId=-1, physicsClientId=client)
    for body, rgba in zip(scene.object_ids, drawn.object_rgbas):
        p.changeVisualShape(body, -1, rgbaColor=list(rgba), physicsClientId=client)
    # The light stands where it shines from: against its direction, far off.
    p.configureDebugVisualizer(lightPosition=[-10.0 * part for part in drawn.light_dir], physicsClientId=client)


def run_viewer(shared_path: Path, urdf: Path, fps: float, task_name: str = "", looks: str = DEFAULT_LOOKS,
               physics: str = DEFAULT_PHYSICS) -> int:
    """The viewer process: a GUI client that shows the angles the physics hands it.

    The window draws nothing until the arm stands at the physics' angles: drawn while
    loading, its links showed one by one, loose at their origins, and drawing them took
    most of the loading time. It loads at the priority it was started with, on one CPU,
    and drops to the lowest once it shows the arm: at the lowest priority from the start,
    a busy machine held the window back by 10 s and more.
    """
    import pybullet as p
    import pybullet_data

    # Ctrl-C in a terminal reaches the whole process group: the physics closes this window.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    keep_to_one_cpu()
    parent = os.getppid()
    mapping, shared = shared_array(shared_path)
    frame_period_s = 1.0 / fps
    try:
        # GUI_MAIN_THREAD: the window draws and reads the mouse only inside this process's
        # PyBullet calls, so it draws when there is something new, not continuously.
        # --nogui: without the side panels from the first frame (COV_ENABLE_GUI 0 from the start).
        client = p.connect(p.GUI_MAIN_THREAD, options="--nogui")
        if client < 0:
            return 1
        shared[STATUS] = OPEN
        p.configureDebugVisualizer(p.COV_ENABLE_RENDERING, 0, physicsClientId=client)
        p.resetDebugVisualizerCamera(**CAMERA, physicsClientId=client)
        p.setAdditionalSearchPath(pybullet_data.getDataPath(), physicsClientId=client)
        plane_id = p.loadURDF("plane.urdf", physicsClientId=client)
        # Nothing collides in a mirror: no collision shapes, which are most of the loading time.
        robot_id = p.loadURDF(str(urdf), useFixedBase=True, flags=p.URDF_IGNORE_COLLISION_SHAPES, physicsClientId=client)
        indices = [joint.index for joint in ACTUATED_JOINTS]
        scene = None
        if task_name:
            from so101.tasks import task_named

            scene = task_named(task_name).pybullet_scene(client, 0)

        shown_layout = -1.0

        def pose(slots: np.ndarray) -> float:
            """The arm (and the task's objects, in their layout's looks) as the shared `slots` have them; returns
            the frame they belong to."""
            nonlocal shown_layout
            frame = slots[FRAME]  # before the angles: the physics writes them, then counts the frame
            p.resetJointStatesMultiDof(
                robot_id, indices, [[angle] for angle in slots[ANGLES:OBJECTS].tolist()], physicsClientId=client,
            )
            if scene is not None:
                if slots[LAYOUT] != shown_layout and slots[LAYOUT] >= 0:
                    shown_layout = float(slots[LAYOUT])
                    show_layout(scene, plane_id, client, int(shown_layout), looks, physics)
                scene.show_object_state(slots[OBJECTS:].tolist())
            return frame

        shown_frame = pose(shared)
        p.configureDebugVisualizer(p.COV_ENABLE_RENDERING, 1, physicsClientId=client)  # draws the posed arm
        shared[STATUS] = SHOWING
        lowest_priority()
        busy_until_s = drawn_at_s = 0.0
        # Ends with the physics: its close() terminates this process; if it died, the parent changes.
        while os.getppid() == parent:
            now_s = time.monotonic()
            if shared[FRAME] != shown_frame:  # the arm moved
                shown_frame = pose(shared)
                busy_until_s, drawn_at_s = now_s + BUSY_FOR_S, now_s
            elif now_s < busy_until_s or now_s - drawn_at_s >= IDLE_PERIOD_S:
                # Draws, and takes the mouse's camera moves; a mouse in use keeps the full frame rate.
                if p.getMouseEvents(physicsClientId=client):
                    busy_until_s = now_s + BUSY_FOR_S
                drawn_at_s = now_s
            time.sleep(frame_period_s)
    except p.error:
        return 0  # the window was closed
    finally:
        del shared  # the view first: a mapping with a view on it cannot close
        mapping.close()
    return 0


def viewer_main(argv: list[str] | None, module: str, description: str, model_option: str, run) -> int:
    """The command line of a viewer process: `python -m MODULE --shared FILE --MODEL PATH [--fps N] [--task NAME]`."""
    parser = argparse.ArgumentParser(prog=f"python -m {module}", description=description)
    parser.add_argument("--shared", type=Path, required=True, help="the file the physics writes the angles to")
    parser.add_argument(f"--{model_option}", type=Path, required=True, help="the arm's model file")
    parser.add_argument("--fps", type=float, default=DEFAULT_FPS, help=f"frames per second at most (default {DEFAULT_FPS:g})")
    parser.add_argument("--task", default="", help="a task's objects to show too (so101.tasks), posed from the shared file")
    parser.add_argument("--looks", choices=LOOKS_CHOICES, default=DEFAULT_LOOKS,
                        help="the run's looks: each layout's colours and light, as its pictures have them")
    parser.add_argument("--physics", default=DEFAULT_PHYSICS,
                        help="the run's physics (fixed, varied, or ranges as JSON): each layout's cube at its size")
    args = parser.parse_args(argv)
    return run(args.shared, getattr(args, model_option), args.fps, args.task, args.looks, args.physics)


def main(argv: list[str] | None = None) -> int:
    return viewer_main(argv, "so101.gui.viewer", __doc__.splitlines()[0], "urdf", run_viewer)


if __name__ == "__main__":
    sys.exit(main())
