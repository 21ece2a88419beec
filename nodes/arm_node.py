"""arm: the real SO-101 follower arm as a dora node, with the simulation's contract (the course's next section).

"Swap one driver node": the same `joint_cmd` input and `joint_state`/`gripper_state`
outputs, in the URDF's degrees, from the same event loop as the simulations
(so101/bodies/node_loop.py); the body is six Feetech STS3215 servos on a serial bus
(so101/bodies/real_arm.py, which holds the safety rules). On STOP, Ctrl-C, SIGTERM, an
error or a lost bus, torque goes off. Its settings, from dataflow_real.yml's `env:`, are
NodeSettings and ArmSettings (so101/bodies/settings.py); the tick is the `tick` timer's (20 ms).
"""

from __future__ import annotations

import os
import signal
import sys
from types import FrameType

from dora import Node

from so101.bodies.node_loop import run_body_node
from so101.bodies.real_arm import ArmFailed, SO101Real, check_node_settings
from so101.bodies.settings import ArmSettings, NodeSettings
from so101.feetech.calibration import CalibrationError
from so101.runtime.logs import send_diagnostics_to
from so101.runtime.node_events import cannot_start


def _interrupt(signum: int, frame: FrameType | None) -> None:
    # SIGTERM (dora's or a person's `kill`) ends the loop like Ctrl-C, through the code that switches torque off.
    raise KeyboardInterrupt


def main() -> int:
    send_diagnostics_to("stdout")  # dora keeps a node's stdout in its log, beside the loaded line
    signal.signal(signal.SIGTERM, _interrupt)
    try:
        settings = NodeSettings.from_environ(os.environ)
        arm_settings = ArmSettings.from_environ(os.environ)
        check_node_settings(settings)
    except ValueError as error:
        return cannot_start(error, "arm")
    try:
        arm = SO101Real.from_settings(arm_settings, settings.lang)
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
