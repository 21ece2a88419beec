"""simulation: the SO-101 in MuJoCo as the same dora node (the course's advanced bridge).

The same contract as nodes/simulation_node.py (the node id, inputs, outputs, units,
clamping, replies to bad commands, STOP and Ctrl-C) from the same event loop
(so101/bodies/node_loop.py), with MuJoCo and TheRobotStudio's MJCF as the body: position
actuators like the STS3215 servos, and joint damping, so exercise 2 means what it says.

Environment (declared in dataflow_mujoco.yml): SO101_MODE, SO101_IMAGE_HZ,
SO101_FAST_STEPS, SO101_TICK_LOG, SO101_LANG (see so101/bodies/node_loop.py), and MuJoCo's own:
  SO101_MUJOCO_DAMPING  every joint's damping in N·m·s/rad; empty = the MJCF's (0.60)
"""

from __future__ import annotations

import os
import sys

from dora import Node

from so101.assets import ModelFilesError
from so101.bodies.node_loop import NodeSettings, cannot_start, check_pictures, log, number_setting, run_body_node
from so101.runtime.dataflow import TICK_PERIOD_S
from so101.gui.display import DisplayError
from so101.bodies.mujoco_sim import SO101MuJoCo


def main() -> int:
    try:
        settings = NodeSettings.from_environ(os.environ)
        damping = None
        if os.environ.get("SO101_MUJOCO_DAMPING", "").strip():
            damping = number_setting(os.environ, "SO101_MUJOCO_DAMPING", "", 0.0)
    except ValueError as error:
        return cannot_start(error)
    try:
        sim = SO101MuJoCo(
            mode=settings.mode, time_step_s=TICK_PERIOD_S, joint_damping_n_m_s=damping, log=log,
            renders=settings.image_hz > 0,
        )
        check_pictures(sim, settings)
    except (ModelFilesError, DisplayError, ValueError) as error:
        return cannot_start(error)
    damping_n_m_s = sim.joint_damping_n_m_s()
    return run_body_node(
        sim, Node(), settings, identity="MuJoCo so101_new_calib.xml",
        detail={"zh": f"关节阻尼 {damping_n_m_s:g} N·m·s/rad", "en": f"joint damping {damping_n_m_s:g} N·m·s/rad"},
    )


if __name__ == "__main__":
    sys.exit(main())
