"""The bodies the simulation node's contract runs on: one entry each, its node file and its dataflow.

`so101 teleop --body`, the tests' contract suite and `tests/test_bodies.py` read this
table, so a body added here is driven and tested like the others.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Body:
    name: str
    node_file: Path  # the `simulation` node's path in the dataflow
    dataflow_file: Path
    simulator: str  # "module:Class" of the body's simulator (SO101Sim's surface)

    def simulator_class(self):
        """The simulator class, imported on first use: each engine is a heavy import."""
        module, name = self.simulator.split(":")
        return getattr(importlib.import_module(module), name)


BODIES = {
    # The course's choice, and the default.
    "pybullet": Body("pybullet", ROOT / "nodes" / "simulation_node.py", ROOT / "dataflow.yml", "so101.simulator:SO101Sim"),
    "mujoco": Body("mujoco", ROOT / "nodes" / "simulation_mujoco.py", ROOT / "dataflow_mujoco.yml",
                   "so101.mujoco_sim:SO101MuJoCo"),
}
DEFAULT_BODY = "pybullet"
