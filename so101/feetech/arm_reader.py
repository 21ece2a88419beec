"""The SO-101 read only: torque switched off and kept off (the arm is moved by hand), its six joint
angles read from the bus, no goal ever written (`so101 cameras --align`)."""

from __future__ import annotations

import time
from pathlib import Path

from so101.feetech.bus import BusError, BusLost, FeetechBus
from so101.feetech.calibration import (
    MOTOR_IDS, MOTOR_NAMES, CalibrationError, load_calibration, steps_to_deg,
)
from so101.feetech.checks import check_calibration_on_servos, check_servos_answer

# A read that fails now and then passes; this many in a row (about two seconds) is an arm gone.
FAILED_READS_AT_MOST = 10
TORQUE_OFF_READS = 3


class ArmReaderError(Exception):
    """An arm that cannot be read (at start, or gone while read); str() is one line for the person."""


class ArmReader:
    """The SO-101 on `port`, with the calibration at `calibration_path`, read only: torque switched off at
    start (it is moved by hand) and again at `close()`, whatever was on; `read_deg()` gives the six joint
    angles (the URDF's degrees). ArmReaderError in one line when it cannot start."""

    def __init__(self, port: str, calibration_path: Path, joint_signs: tuple[int, ...] = (1,) * 6):
        self.port = port
        try:
            calibration = load_calibration(calibration_path)
        except CalibrationError as error:
            raise ArmReaderError(str(error)) from None
        self._motors = [calibration[name] for name in MOTOR_NAMES]
        self._signs = joint_signs
        self.failed_reads = 0
        self.bus: FeetechBus | None = None
        try:
            bus = self.bus = FeetechBus(port).open()
            check_servos_answer(bus)
            check_calibration_on_servos(bus, self._motors, str(calibration_path), "arm",
                                        "calibrate it (`so101 calibrate`) or give its own file")
            bus.sync_write("Torque_Enable", {servo_id: 0 for servo_id in MOTOR_IDS})
        except (BusError, CalibrationError) as error:
            self.close()
            raise ArmReaderError(str(error)) from None
        except BaseException:
            self.close()
            raise

    def read_deg(self) -> tuple[float, ...] | None:
        """The six angles now; None when this read failed. ArmReaderError once the arm is gone (its port lost,
        or FAILED_READS_AT_MOST reads failed in a row)."""
        if self.bus is None:
            return None
        try:
            present = self.bus.sync_read("Present_Position", MOTOR_IDS)
        except BusLost as error:
            raise ArmReaderError(f"the arm on {self.port} is gone ({error})") from None
        except BusError as error:
            self.failed_reads += 1
            if self.failed_reads >= FAILED_READS_AT_MOST:
                raise ArmReaderError(f"the arm on {self.port} stopped answering ({error}; {self.failed_reads} reads "
                                     "failed in a row)") from None
            return None
        self.failed_reads = 0
        return tuple(steps_to_deg(index, present[servo_id], motor, sign)
                     for index, (servo_id, motor, sign) in enumerate(zip(MOTOR_IDS, self._motors, self._signs)))

    def close(self) -> str | None:
        """Torque off on every servo (confirmed by reading it back), then the port closed; None when done,
        else the line that says torque could not be confirmed off. Safe twice."""
        bus, self.bus = self.bus, None
        if bus is None:
            return None
        try:
            bus.sync_write("Torque_Enable", {servo_id: 0 for servo_id in MOTOR_IDS})
            # An "on" is read again before it is believed: Ctrl-C can leave an old reply on the line.
            for _ in range(TORQUE_OFF_READS):
                if not any(bus.sync_read("Torque_Enable", MOTOR_IDS).values()):
                    return None
                time.sleep(0.02)
            return "a servo still reports torque on: switch the arm's power off"
        except BusError as error:
            return f"could not confirm torque off ({error}): switch the arm's power off"
        finally:
            bus.close()
