"""The bodies the simulation node's contract runs on: one row each, its node file, its dataflow and its settings.

`so101 teleop --body`, the tests' contract suite and `tests/test_bodies.py` read this
table, so a body added here is driven and tested like the others. The real arm is a body
too: its node (id `arm`) speaks the same contract to six servos instead of a simulator.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from so101.bodies.protocol import BodyName
from so101.bodies.settings import ArmSettings, MuJoCoSettings, PyBulletSettings
from so101.runtime.dataflow import ROOT
from so101.runtime.settings import EnvironSettings


@dataclass(frozen=True)
class BodyKind:
    """A row of the table: one kind of body (the live body is so101.bodies.protocol.Body)."""

    name: BodyName  # the body's `kind`
    node_file: Path  # the body node's path in the dataflow
    dataflow_file: Path
    class_path: str  # "module:Class" of the body (so101.bodies.protocol.Body)
    settings: type[EnvironSettings]  # the body's own settings, read by its node besides NodeSettings
    node_id: str = "simulation"  # the body node's id in the dataflow
    simulated: bool = True  # False: hardware (no window, no camera, no physics to step ahead)

    def body_class(self) -> Any:
        """The body's class, imported on first use: each engine is a heavy import. Any, for the
        classes' constructors differ (a simulator's display mode and step, the arm's port)."""
        module, name = self.class_path.split(":")
        return getattr(importlib.import_module(module), name)


BODIES = {
    # The course's choice, and the default.
    "pybullet": BodyKind("pybullet", ROOT / "nodes" / "simulation_node.py", ROOT / "dataflow.yml",
                         "so101.bodies.pybullet_sim:SO101Sim", PyBulletSettings),
    "mujoco": BodyKind("mujoco", ROOT / "nodes" / "simulation_mujoco.py", ROOT / "dataflow_mujoco.yml",
                       "so101.bodies.mujoco_sim:SO101MuJoCo", MuJoCoSettings),
    # The course's next section: the same contract on a real SO-101 follower (or `so101 fake-arm`).
    "real": BodyKind("real", ROOT / "nodes" / "arm_node.py", ROOT / "dataflow_real.yml",
                     "so101.bodies.real_arm:SO101Real", ArmSettings, node_id="arm", simulated=False),
}
SIMULATED_BODIES = [name for name, body in BODIES.items() if body.simulated]
DEFAULT_BODY = "pybullet"


def body_node_env(body: BodyKind, port: str | None, calibration: str | None) -> dict[str, str]:
    """The body node's settings that come from the command line: the real arm's serial port and
    calibration file (SO101_PORT, SO101_CALIBRATION). ValueError, in one line, when the real arm
    lacks them or a simulated body is given them."""
    if body.simulated:
        if port or calibration:
            raise ValueError(f"--port and --calibration are for --body real, not {body.name}")
        return {}
    if not port or not calibration:
        raise ValueError("--body real needs --port PORT and --calibration FILE "
                         "(no arm? `so101 fake-arm` emulates one; `so101 calibrate` makes the file)")
    return {"SO101_PORT": port, "SO101_CALIBRATION": calibration}
