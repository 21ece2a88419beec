"""The physics' side of a window: a viewer in a process of its own (so101.gui), fed the angles.

A body that shows a window (PyBullet's or MuJoCo's, in GUI mode) starts the viewer's module in
another process and shares one small file with it, mapped into both: a frame counter, the
viewer's state, the seed of the layout shown, the six joint angles in radians
(so101.robot.ACTUATED_JOINTS order) and, with a task, its objects' poses (its object_state). The
viewer draws; the physics never waits for it. Told the run's looks and physics (`--looks varied`,
`--physics varied`), the viewer draws each layout's as its seed has them: what the pictures show.
"""

from __future__ import annotations

import mmap
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import numpy.typing as npt

from so101.bodies.looks import DEFAULT_LOOKS
from so101.bodies.physics import DEFAULT_PHYSICS
from so101.bodies.protocol import BodyFailed
from so101.robot import ACTUATED_JOINTS
from so101.runtime.dataflow import ROOT
from so101.runtime.processes import stop_process

DEFAULT_FPS = 30.0
# Slots of the shared file, float64 each.
FRAME, STATUS, LAYOUT, ANGLES = 0, 1, 2, 3
NO_LAYOUT = -1.0  # LAYOUT before a task's first layout (seeds are whole numbers from 0)
OBJECTS = ANGLES + len(ACTUATED_JOINTS)
STARTING, OPEN, SHOWING = 0.0, 1.0, 2.0  # the window: not yet, open, showing the arm
# Differences below these are not drawn (a hundredth of a degree; a tenth of a millimetre).
STILL_RAD = 1.7e-4
STILL_M = 1e-4

# Logged once the window shows the arm, posed: a few seconds after the physics starts.
WINDOW_SHOWING = "window open: it shows the arm as the physics moves it"


class WindowClosed(BodyFailed):
    """The window's process ended: closed by the person, or it could not open."""


def shared_array(path: Path) -> tuple[mmap.mmap, npt.NDArray[np.float64]]:
    """The shared file mapped, as float64 slots: the angles' slots, then as many as the objects need."""
    with open(path, "r+b") as handle:
        mapping = mmap.mmap(handle.fileno(), 0)
    return mapping, np.ndarray((len(mapping) // 8,), dtype=np.float64, buffer=mapping)


class Window:
    """The physics side: starts a viewer process and hands it the angles, at most `fps` times a second.

    `viewer` is the viewer's module with its model options: PyBullet's window
    (`["so101.gui.viewer", "--urdf", URDF]`) or MuJoCo's (`["so101.gui.mujoco_viewer", "--mjcf", MJCF]`);
    both take `--shared FILE --fps N` and keep to this file's shared slots. `object_values` is
    how many numbers a task's object_state has (0: the arm alone). `looks` and `physics` (modes, as
    so101.bodies.looks and so101.bodies.physics take them) are the run's: the viewer draws each layout's.
    """

    def __init__(self, viewer: list[str], fps: float = DEFAULT_FPS, on_showing: Callable[[], None] = lambda: None,
                 object_values: int = 0, looks: str = DEFAULT_LOOKS, physics: str = DEFAULT_PHYSICS):
        """`on_showing` is called once, from show(), when the window first shows the arm."""
        self.frame_period_s = 1.0 / fps
        self.showing = False
        self._on_showing = on_showing
        handle, name = tempfile.mkstemp(prefix="so101-window-", suffix=".bin")
        with os.fdopen(handle, "wb") as shared:
            shared.write(bytes((OBJECTS + object_values) * 8))
        self._path = Path(name)
        self._mapping, self._shared = shared_array(self._path)
        self._shared[LAYOUT] = NO_LAYOUT
        self._next_frame_s = 0.0
        scenario = [*(["--looks", looks] if looks != DEFAULT_LOOKS else []),
                    *(["--physics", physics] if physics != DEFAULT_PHYSICS else [])]
        self.process = subprocess.Popen(
            [sys.executable, "-m", *viewer, "--shared", str(self._path), "--fps", f"{fps:g}", *scenario],
            # The GUIs chatter on stdout (GL versions, threads); their errors, such as
            # "X connection ... broken", stay on stderr, in the node's log.
            stdout=subprocess.DEVNULL,
            env=dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))),
        )

    def due(self) -> bool:
        """Whether a new frame is due (cheap: the physics asks after every step)."""
        return time.monotonic() >= self._next_frame_s

    def show(self, angles_rad: Sequence[float] | npt.NDArray[np.float64],
             object_state: Sequence[float] | npt.NDArray[np.float32] | None = None, layout_seed: int | None = None) -> None:
        """Hand the viewer the latest angles (and a task's object_state and the seed of its layout, if any);
        raises WindowClosed once its process has ended."""
        self._next_frame_s = time.monotonic() + self.frame_period_s
        code = self.process.poll()
        if code is not None:
            opened = self._shared[STATUS] >= OPEN
            raise WindowClosed(
                "the window was closed" if opened
                else f"the window could not open, or was closed while it opened (its process exited with code {code})"
            )
        if not self.showing and self._shared[STATUS] == SHOWING:
            self.showing = True
            self._on_showing()
        # A new frame only when something moved: a still scene costs the viewer nothing.
        angles = np.asarray(angles_rad, dtype=np.float64)
        moved = bool(np.any(np.abs(self._shared[ANGLES:OBJECTS] - angles) > STILL_RAD))
        if layout_seed is not None and self._shared[LAYOUT] != layout_seed:  # before the objects: the viewer lays it out first
            self._shared[LAYOUT] = layout_seed
            moved = True
        if object_state is not None and np.any(np.abs(self._shared[OBJECTS:] - np.asarray(object_state)) > STILL_M):
            self._shared[OBJECTS:] = object_state
            moved = True
        if moved:
            self._shared[ANGLES:OBJECTS] = angles
            self._shared[FRAME] += 1

    def close(self) -> None:
        """Close the window and its process; safe to call twice."""
        stop_process(self.process, 5, first_signal=signal.SIGTERM)
        if not self._mapping.closed:
            del self._shared  # the view first: a mapping with a view on it cannot close
            self._mapping.close()
        self._path.unlink(missing_ok=True)
