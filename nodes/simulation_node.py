"""simulation: the SO-101 in PyBullet as a dora node (course step C).

Each `tick` advances the physics by one step of the tick's period and publishes
`joint_state`; a `joint_cmd` sets the targets the next tick applies. The event loop is
shared with every body (so101/bodies/node_loop.py); this file sets up PyBullet. Its
settings, from dataflow.yml's `env:`, are NodeSettings and PyBulletSettings
(so101/bodies/settings.py).
"""

from __future__ import annotations

import os
import sys

from dora import Node

from so101.assets import ModelFilesError
from so101.bodies.node_loop import announce, run_body_node
from so101.bodies.task_cameras import node_cameras
from so101.bodies.pybullet_sim import SO101Sim, release_freed_memory
from so101.bodies.settings import NodeSettings, PyBulletSettings
from so101.runtime.display import DisplayError
from so101.runtime.logs import send_diagnostics_to
from so101.runtime.node_events import cannot_start
from so101.tasks import task_for_setting


def main() -> int:
    send_diagnostics_to("stdout")  # dora keeps a node's stdout in its log, beside the loaded line
    try:
        settings = NodeSettings.from_environ(os.environ)
        task = task_for_setting(settings.task)  # its scene, which it hands to the body
        pybullet = PyBulletSettings.from_environ(os.environ)
    except ValueError as error:
        return cannot_start(error)
    # Course step C's setup_pybullet. The arm is loaded before joining the dataflow:
    # ticks that arrive while the URDF loads would only be discarded, one warning each.
    release_freed_memory()
    try:
        sim = SO101Sim.from_settings(pybullet, settings, task, log=announce)
        cameras = node_cameras(task, settings, pybullet.assets_dir, log=announce)
    except (ModelFilesError, DisplayError, ValueError) as error:
        return cannot_start(error)
    # Course step C's `for event in node:` loop, shared with every body.
    return run_body_node(
        sim, Node(), settings, cameras=cameras, identity=f"robot_id = {sim.robot_id}",
        detail={"zh": f"{sim.control_mode} 控制", "en": f"{sim.control_mode} control"},
    )


if __name__ == "__main__":
    sys.exit(main())
