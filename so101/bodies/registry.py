"""The bodies the simulation node's contract runs on: one entry each, its node file and its dataflow.

`so101 teleop --body`, the tests' contract suite and `tests/test_bodies.py` read this
table, so a body added here is driven and tested like the others. The real arm is a body
too: its node (id `arm`) speaks the same contract to six servos instead of a simulator.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


class BodyFailed(Exception):
    """A body that cannot start or go on (the real arm's bus, ...); str() is one line for the user."""


@dataclass(frozen=True)
class Body:
    name: str
    node_file: Path  # the body node's path in the dataflow
    dataflow_file: Path
    simulator: str  # "module:Class" of the body's simulator (SO101Sim's surface)
    node_id: str = "simulation"  # the body node's id in the dataflow
    simulated: bool = True  # False: hardware (no window, no camera, no physics to step ahead)

    def simulator_class(self):
        """The simulator class, imported on first use: each engine is a heavy import."""
        module, name = self.simulator.split(":")
        return getattr(importlib.import_module(module), name)


BODIES = {
    # The course's choice, and the default.
    "pybullet": Body("pybullet", ROOT / "nodes" / "simulation_node.py", ROOT / "dataflow.yml", "so101.bodies.pybullet_sim:SO101Sim"),
    "mujoco": Body("mujoco", ROOT / "nodes" / "simulation_mujoco.py", ROOT / "dataflow_mujoco.yml",
                   "so101.bodies.mujoco_sim:SO101MuJoCo"),
    # The course's next section: the same contract on a real SO-101 follower (or `so101 fake-arm`).
    "real": Body("real", ROOT / "nodes" / "arm_node.py", ROOT / "dataflow_real.yml", "so101.bodies.real_arm:SO101Real",
                 node_id="arm", simulated=False),
}
SIMULATED_BODIES = [name for name, body in BODIES.items() if body.simulated]
DEFAULT_BODY = "pybullet"


def body_node_env(body: Body, port: str | None, calibration: str | None) -> dict[str, str]:
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
