"""An emulated SO-101 servo bus (`so101 fake-arm`), in rooms: the wire protocol (protocol.py), one
servo's registers and motion (servo.py), the assembled arm's mechanics (mechanics.py), a hand moving
the joints (hand_paths.py), injected faults (faults.py), the bus itself (arm.py) and the bus in a
process of its own, for tests (process.py)."""

from so101.feetech.fake_arm.arm import FakeArm, calibrate_as_at_the_factory
from so101.feetech.fake_arm.mechanics import (
    ALL_IDS, MECHANICAL_TABLE, MECHANICS, Mechanics, joint_deg, physical_steps,
)
from so101.feetech.fake_arm.process import FakeArmProcess
from so101.feetech.fake_arm.protocol import checksum, instruction_packet
from so101.feetech.fake_arm.servo import DEFAULT_SPEED_STEPS_S, Response

__all__ = [
    "ALL_IDS", "DEFAULT_SPEED_STEPS_S", "MECHANICAL_TABLE", "MECHANICS", "FakeArm", "FakeArmProcess", "Mechanics", "Response",
    "calibrate_as_at_the_factory", "checksum", "instruction_packet", "joint_deg", "physical_steps",
]
