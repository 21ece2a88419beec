"""What a driver checks before it trusts the servos on a bus: the follower's (so101/bodies/real_arm.py),
the leader's (so101/leader/arm.py) and `so101 calibrate`'s. Each check raises with one line for the user."""

from __future__ import annotations

from typing import Callable, Sequence, TypeVar

from so101.feetech.bus import BusError, FeetechBus, NoPort
from so101.feetech.calibration import MOTOR_IDS, MOTOR_NAMES, CalibrationError, MotorCalibration
from so101.feetech.sts3215 import MODEL_NUMBER, SIGN_BITS, decode_signed

# A ping or read at start is asked up to START_ATTEMPTS times before a servo is called silent: real
# Feetech buses lose the odd reply ("There is no status packet", LeRobot issue #1252, whose users
# needed num_retry=3), and pings and reads change nothing on a servo, so asking again is safe. A
# servo that is really missing costs three packet timeouts, about 0.1 s.
START_ATTEMPTS = 3

Answer = TypeVar("Answer")


def at_start(ask: Callable[[], Answer]) -> Answer:
    """`ask()` (a ping or a read), asked up to START_ATTEMPTS times while it raises BusError or answers
    None; the last error or answer stands. No port at all is said at once."""
    attempt = 0
    while True:
        attempt += 1
        patience_left = attempt < START_ATTEMPTS
        try:
            answer = ask()
        except NoPort:
            raise
        except BusError:
            if not patience_left:
                raise
            continue
        if answer is not None or not patience_left:
            return answer


def check_servos_answer(bus: FeetechBus) -> None:
    """Every servo of an SO-101 answers at its ID and is an STS3215; BusError names the first that is not."""
    for name, servo_id in zip(MOTOR_NAMES, MOTOR_IDS):
        model = at_start(lambda: bus.ping(servo_id))
        if model is None:
            raise BusError(f"servo {servo_id} ({name}) does not answer on {bus.port_name}: "
                           f"check its power and cable, and that it has ID {servo_id}")
        if model != MODEL_NUMBER:
            raise BusError(f"servo {servo_id} ({name}) is model {model}, not an STS3215 ({MODEL_NUMBER})")


def check_calibration_on_servos(bus: FeetechBus, motors: Sequence[MotorCalibration], calibration_name: str,
                                which_arm: str, remedy: str) -> None:
    """The servos hold the calibration's offsets and ranges (a calibration writes them into their EEPROM) and are
    in position mode; CalibrationError names the first servo that differs, then `remedy`. `which_arm`: "arm",
    "leader", as the line calls it."""
    for name, servo_id, motor in zip(MOTOR_NAMES, MOTOR_IDS, motors):
        on_servo = {
            "homing_offset": decode_signed(at_start(lambda: bus.read(servo_id, "Homing_Offset")),
                                           SIGN_BITS["Homing_Offset"]),
            "range_min": at_start(lambda: bus.read(servo_id, "Min_Position_Limit")),
            "range_max": at_start(lambda: bus.read(servo_id, "Max_Position_Limit")),
        }
        for field_name, value in on_servo.items():
            if value != getattr(motor, field_name):
                raise CalibrationError(
                    f"{calibration_name} does not match the {which_arm} on {bus.port_name}: servo {servo_id} ({name}) "
                    f"has {field_name} {value}, the file says {getattr(motor, field_name)}; {remedy}")
        if at_start(lambda: bus.read(servo_id, "Operating_Mode")) != 0:
            raise CalibrationError(f"servo {servo_id} ({name}) is not in position mode (Operating_Mode 0)")
