"""The PyBullet window, in a process of its own that mirrors the arm's joint angles.

In PyBullet's GUI mode every API call waits for the window's render thread, so on a
machine with slow graphics (software OpenGL, a virtual machine, WSL) the physics runs
at the window's frame rate: 84 steps a second instead of 250 under Xvfb here. So the
physics always runs in its own DIRECT client, and the window is a second PyBullet
client, in another process and at a lower priority, that loads the same arm, never
steps it, and sets its joints to the latest angles at most `fps` times a second.
The window keeps PyBullet's own camera controls (drag to rotate, wheel to zoom,
Ctrl-drag to pan).

The two processes share one small file, mapped into both: a frame counter, the
viewer's state, and the six joint angles in radians (so101.robot.ACTUATED_JOINTS order).

    python -m so101.viewer --shared FILE [--fps N]    (started by `Window`, not by hand)
"""

from __future__ import annotations

import argparse
import mmap
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from so101.robot import ACTUATED_JOINTS

DEFAULT_FPS = 30.0
# Slots of the shared file, float64 each.
FRAME, STATUS, ANGLES = 0, 1, 2
SLOTS = ANGLES + len(ACTUATED_JOINTS)
STARTING, OPEN = 0.0, 1.0
# The viewer's own niceness: the window must never take a CPU from the physics.
VIEWER_NICENESS = 10
# Where the course points its camera (and where this project's window always has).
CAMERA = {"cameraDistance": 0.6, "cameraYaw": 45, "cameraPitch": -30, "cameraTargetPosition": [0, 0, 0.15]}


class WindowClosed(RuntimeError):
    """The window's process ended: closed by the person, or it could not open."""


def _shared_array(path: Path) -> tuple[mmap.mmap, np.ndarray]:
    with open(path, "r+b") as handle:
        mapping = mmap.mmap(handle.fileno(), SLOTS * 8)
    return mapping, np.ndarray((SLOTS,), dtype=np.float64, buffer=mapping)


class Window:
    """The physics side: starts the viewer process and hands it the angles, at most `fps` times a second."""

    def __init__(self, urdf: Path, fps: float = DEFAULT_FPS):
        self.frame_period_s = 1.0 / fps
        handle, name = tempfile.mkstemp(prefix="so101-window-", suffix=".bin")
        with os.fdopen(handle, "wb") as shared:
            shared.write(bytes(SLOTS * 8))
        self._path = Path(name)
        self._mapping, self._shared = _shared_array(self._path)
        self._next_frame_s = 0.0
        self.process = subprocess.Popen(
            [sys.executable, "-m", "so101.viewer", "--shared", str(self._path), "--urdf", str(urdf), "--fps", f"{fps:g}"],
            # PyBullet's GUI chatters on stdout (GL versions, threads); its errors, such as
            # "X connection ... broken", stay on stderr, in the node's log.
            stdout=subprocess.DEVNULL,
            env=dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(Path(__file__).resolve().parents[1]),
                                                                           os.environ.get("PYTHONPATH")]))),
        )

    def due(self) -> bool:
        """Whether a new frame is due (cheap: the physics asks after every step)."""
        return time.monotonic() >= self._next_frame_s

    def show(self, angles_rad) -> None:
        """Hand the viewer the latest angles; raises WindowClosed once its process has ended."""
        self._next_frame_s = time.monotonic() + self.frame_period_s
        code = self.process.poll()
        if code is not None:
            opened = self._shared[STATUS] == OPEN
            raise WindowClosed(
                "the window was closed" if opened else f"the window could not open (its process exited with code {code})"
            )
        self._shared[ANGLES:] = angles_rad
        self._shared[FRAME] += 1

    def close(self) -> None:
        """Close the window and its process; safe to call twice."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if not self._mapping.closed:
            self._shared = None
            self._mapping.close()
        self._path.unlink(missing_ok=True)


def run_viewer(shared_path: Path, urdf: Path, fps: float) -> int:
    """The viewer process: a GUI client that shows the angles the physics hands it."""
    import signal

    import pybullet as p
    import pybullet_data

    # Ctrl-C in a terminal reaches the whole process group: the physics closes this window.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        os.nice(VIEWER_NICENESS)
    except OSError:
        pass  # not allowed here: run at the same priority
    parent = os.getppid()
    mapping, shared = _shared_array(shared_path)
    frame_period_s = 1.0 / fps
    # The render thread draws no more often than the frames come (the option is in µs).
    client = p.connect(p.GUI, options=f"--minGraphicsUpdateTimeMs={int(frame_period_s * 1e6)}")
    if client < 0:
        return 1
    shared[STATUS] = OPEN
    p.configureDebugVisualizer(p.COV_ENABLE_GUI, 0, physicsClientId=client)
    p.resetDebugVisualizerCamera(**CAMERA, physicsClientId=client)
    p.setAdditionalSearchPath(pybullet_data.getDataPath(), physicsClientId=client)
    p.loadURDF("plane.urdf", physicsClientId=client)
    robot_id = p.loadURDF(str(urdf), useFixedBase=True, physicsClientId=client)
    indices = [joint.index for joint in ACTUATED_JOINTS]
    shown_frame = -1.0
    try:
        # Ends with the physics: its close() terminates this process; if it died, the parent changes.
        while os.getppid() == parent:
            frame = shared[FRAME]
            if frame != shown_frame:
                shown_frame = frame
                p.resetJointStatesMultiDof(
                    robot_id, indices, [[angle] for angle in shared[ANGLES:].tolist()], physicsClientId=client,
                )
            time.sleep(frame_period_s)
    except p.error:
        return 0  # the window was closed
    finally:
        shared = None
        mapping.close()
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m so101.viewer", description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, required=True, help="the file the physics writes the angles to")
    parser.add_argument("--urdf", type=Path, required=True, help="the arm's URDF")
    parser.add_argument("--fps", type=float, default=DEFAULT_FPS, help=f"frames per second at most (default {DEFAULT_FPS:g})")
    args = parser.parse_args(argv)
    return run_viewer(args.shared, args.urdf, args.fps)


if __name__ == "__main__":
    sys.exit(main())
