"""Feetech STS3215 facts: the registers this project touches, from Feetech's STS memory table.

One place for the driver (so101/feetech/bus.py), the calibration command and the emulator
(so101/feetech/fake_arm.py). Multi-byte registers are little-endian. Values that can be negative
use a sign bit (not two's complement): bit 11 for Homing_Offset, bit 15 for the velocities.
"""

from __future__ import annotations

MODEL_NUMBER = 777  # what an STS3215 answers at Model_Number
BAUD_RATE = 1_000_000  # the SO-101's bus (Baud_Rate register value 0)
STEPS_PER_TURN = 4096  # the magnetic encoder's resolution
MAX_STEP = STEPS_PER_TURN - 1

# name: (address, size in bytes)
REGISTERS: dict[str, tuple[int, int]] = {
    # EEPROM: kept through a power cycle; written only with torque off and Lock = 0.
    "Model_Number": (3, 2),
    "ID": (5, 1),
    "Baud_Rate": (6, 1),
    "Return_Delay_Time": (7, 1),
    "Min_Position_Limit": (9, 2),
    "Max_Position_Limit": (11, 2),
    "Max_Torque_Limit": (16, 2),
    "P_Coefficient": (21, 1),
    "D_Coefficient": (22, 1),
    "I_Coefficient": (23, 1),
    "Homing_Offset": (31, 2),
    "Operating_Mode": (33, 1),  # 0 = position mode
    # RAM
    "Torque_Enable": (40, 1),
    "Acceleration": (41, 1),
    "Goal_Position": (42, 2),
    "Goal_Time": (44, 2),
    "Goal_Velocity": (46, 2),
    "Torque_Limit": (48, 2),
    "Lock": (55, 1),
    "Present_Position": (56, 2),
    "Present_Velocity": (58, 2),
    "Present_Load": (60, 2),
    "Present_Voltage": (62, 1),
    "Present_Temperature": (63, 1),
    "Moving": (66, 1),
    "Present_Current": (69, 2),
}
SIGN_BITS = {"Homing_Offset": 11, "Goal_Velocity": 15, "Present_Velocity": 15}
EEPROM_END = 40  # addresses below this are EEPROM


def encode_signed(value: int, sign_bit: int) -> int:
    """A signed value as the servo stores it: magnitude, with `sign_bit` set when negative."""
    magnitude = abs(int(value))
    if magnitude >= 1 << sign_bit:
        raise ValueError(f"{value} does not fit in {sign_bit} bits and a sign")
    return magnitude | (1 << sign_bit) if value < 0 else magnitude


def decode_signed(raw: int, sign_bit: int) -> int:
    magnitude = raw & ((1 << sign_bit) - 1)
    return -magnitude if raw & (1 << sign_bit) else magnitude
