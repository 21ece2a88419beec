"""simulation: the SO-101 in PyBullet as a dora node (course step C).

Each `tick` advances the physics by one step of the tick's own period (with the
course's motor calls for a new goal first) and publishes `joint_state`. A `joint_cmd` only
updates the targets; the next tick applies them. When dora had to drop ticks
because the node was late (a busy machine), the next tick takes the steps of the
dropped ones too, so simulated time keeps pace with the wall clock. The event loop is
shared with the MuJoCo body (so101/bodies/node_loop.py); this file sets up PyBullet.

Environment (declared in dataflow.yml): SO101_MODE, SO101_IMAGE_HZ, SO101_FAST_STEPS,
SO101_TICK_LOG, SO101_LANG (see so101/bodies/node_loop.py), and PyBullet's own:
  SO101_CONTROL     position | servo      (position is the course's POSITION_CONTROL)
  SO101_SERVO_ZETA  damping ratio of the servo model (servo mode only)
"""

from __future__ import annotations

import os
import sys

from dora import Node

from so101.assets import ModelFilesError
from so101.bodies.node_loop import NodeSettings, cannot_start, check_pictures, log, number_setting, run_body_node
from so101.runtime.dataflow import TICK_PERIOD_S
from so101.gui.display import DisplayError
from so101.bodies.pybullet_sim import SO101Sim, release_freed_memory


def main() -> int:
    try:
        settings = NodeSettings.from_environ(os.environ)
        control_mode = os.environ.get("SO101_CONTROL", "position")
        servo_zeta = number_setting(os.environ, "SO101_SERVO_ZETA", "0.7", 0.0)
    except ValueError as error:
        return cannot_start(error)
    # Course step C's setup_pybullet. The arm is loaded before joining the dataflow:
    # ticks that arrive while the URDF loads would only be discarded, one warning each.
    release_freed_memory()
    try:
        sim = SO101Sim(
            mode=settings.mode, time_step_s=TICK_PERIOD_S, control_mode=control_mode,
            servo_damping_ratio=servo_zeta, log=log, renders=settings.image_hz > 0,
        )
        check_pictures(sim, settings)
    except (ModelFilesError, DisplayError, ValueError) as error:
        return cannot_start(error)
    # Course step C's `for event in node:` loop, shared with every body.
    return run_body_node(
        sim, Node(), settings, identity=f"robot_id = {sim.robot_id}",
        detail={"zh": f"{control_mode} 控制", "en": f"{control_mode} control"},
    )


if __name__ == "__main__":
    sys.exit(main())
