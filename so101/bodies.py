"""The bodies the simulation node's contract runs on: one entry each, its node file and its dataflow.

`so101 teleop --body`, the tests' contract suite and `tests/test_bodies.py` read this
table, so a body added here is driven and tested like the others.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Body:
    name: str
    node_file: Path  # the `simulation` node's path in the dataflow
    dataflow_file: Path


BODIES = {
    # The course's choice, and the default.
    "pybullet": Body("pybullet", ROOT / "nodes" / "simulation_node.py", ROOT / "dataflow.yml"),
    "mujoco": Body("mujoco", ROOT / "nodes" / "simulation_mujoco.py", ROOT / "dataflow_mujoco.yml"),
}
DEFAULT_BODY = "pybullet"
