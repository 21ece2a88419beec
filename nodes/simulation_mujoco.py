"""simulation: the SO-101 in MuJoCo as the same dora node (the course's advanced bridge).

The same contract as nodes/simulation_node.py, from the same event loop
(so101/bodies/node_loop.py), with TheRobotStudio's MJCF as the body: position actuators
like the STS3215 servos, and joint damping, so exercise 2 means what it says. Its settings,
from dataflow_mujoco.yml's `env:`, are NodeSettings and MuJoCoSettings (so101/bodies/settings.py).
"""

from __future__ import annotations

import os
import sys

from dora import Node

from so101.assets import ModelFilesError
from so101.bodies.mujoco_sim import SO101MuJoCo
from so101.bodies.node_loop import announce, run_body_node
from so101.bodies.task_cameras import node_cameras
from so101.bodies.settings import MuJoCoSettings, NodeSettings
from so101.runtime.display import DisplayError
from so101.runtime.logs import send_diagnostics_to
from so101.runtime.node_events import cannot_start
from so101.tasks import task_for_setting


def main() -> int:
    send_diagnostics_to("stdout")  # dora keeps a node's stdout in its log, beside the loaded line
    try:
        settings = NodeSettings.from_environ(os.environ)
        task = task_for_setting(settings.task)  # its scene, which it hands to the body
        mujoco = MuJoCoSettings.from_environ(os.environ)
    except ValueError as error:
        return cannot_start(error)
    try:
        sim = SO101MuJoCo.from_settings(mujoco, settings, task, log=announce)
        cameras = node_cameras(task, settings, mujoco.assets_dir, log=announce)
    except (ModelFilesError, DisplayError, ValueError) as error:
        return cannot_start(error)
    damping_n_m_s = sim.joint_damping_n_m_s()
    return run_body_node(
        sim, Node(), settings, cameras=cameras, identity="MuJoCo so101_new_calib.xml",
        detail={"zh": f"关节阻尼 {damping_n_m_s:g} N·m·s/rad", "en": f"joint damping {damping_n_m_s:g} N·m·s/rad"},
    )


if __name__ == "__main__":
    sys.exit(main())
