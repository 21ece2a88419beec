"""arm: the real SO-101 follower arm as a dora node, with the simulation's contract (the course's next section).

"Swap one driver node": the same `joint_cmd` input and `joint_state`/`gripper_state`
outputs, in the URDF's degrees, from the same event loop as the simulations
(so101/bodies/node_loop.py); the body is six Feetech STS3215 servos on a serial bus
(so101/bodies/real_arm.py, which holds the safety rules). Each `tick` sends the ramped goals
with one SYNC WRITE and reads the angles with one SYNC READ. On STOP, Ctrl-C, SIGTERM,
an error or a lost bus, torque goes off.

Environment (declared in dataflow_real.yml): SO101_LANG and SO101_TICK_LOG (see
so101/bodies/node_loop.py), and the arm's own:
  SO101_PORT             the serial port (/dev/ttyACM0, ...; `so101 fake-arm` prints an emulated one)
  SO101_CALIBRATION      LeRobot's so101_follower calibration JSON, or one from `so101 calibrate`
  SO101_MAX_SPEED_DEG_S  how fast a goal may move, °/s (each tick moves it by this x the tick period)
  SO101_JOINT_SIGNS      six 1/-1: flips a joint whose direction does not match the URDF
  SO101_TORQUE_LIMIT     % of the servos' maximum torque (lower it to try a new arm safely)
  SO101_BUS_RETRIES      ticks a servo may fail to answer before the node gives up
The tick period is the `tick` timer's own (dora/timer/millis/20).
"""

from __future__ import annotations

import os
import signal
import sys

from dora import Node

from so101.bodies.node_loop import NodeSettings, cannot_start, log, run_body_node
from so101.feetech.calibration import CalibrationError
from so101.bodies.real_arm import ArmFailed, ArmSettings, SO101Real


def _interrupt(signum, frame):
    # SIGTERM (dora's or a person's `kill`) ends the loop like Ctrl-C, through the code that switches torque off.
    raise KeyboardInterrupt


def main() -> int:
    signal.signal(signal.SIGTERM, _interrupt)
    try:
        settings = NodeSettings.from_environ(os.environ)
        arm_settings = ArmSettings.from_environ(os.environ)
        if settings.image_hz > 0:
            raise ValueError("the real arm has no camera: set SO101_IMAGE_HZ to 0")
    except ValueError as error:
        return cannot_start(error, "arm")
    try:
        arm = SO101Real.from_settings(arm_settings, log=log)
    except (CalibrationError, ArmFailed) as error:
        return cannot_start(error, "arm")
    except KeyboardInterrupt:
        return 0
    return run_body_node(
        arm, Node(), settings, identity=f"{arm.port}, {arm_settings.calibration_file.name}",
        detail={"zh": f"总线往返 {arm.round_trip_summary()}", "en": f"bus round trip {arm.round_trip_summary()}"},
        node_id="arm",
    )


if __name__ == "__main__":
    sys.exit(main())
