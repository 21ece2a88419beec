"""Faults a test or a person injects into the emulated bus: a servo that obeys but never replies,
one whose replies carry a wrong checksum, or every reply lost (a broken return line, servo power
gone, as the host sees it)."""

from __future__ import annotations

from typing import Sequence

from so101.feetech.fake_arm.protocol import status_packet
from so101.feetech.fake_arm.servo import Servo

ANSWERS, SILENT, CORRUPT, MUTED = "answers", "silent", "corrupt", "muted"


class Faults:
    """Each servo's reply fault, by its power-up ID, and whether the whole bus is muted."""

    def __init__(self, ids: Sequence[int]):
        self.muted = False
        self._fault = dict.fromkeys(ids, ANSWERS)

    def set(self, servo_id: int, fault: str) -> None:
        """`fault`: ANSWERS (cleared), SILENT or CORRUPT."""
        if fault not in (ANSWERS, SILENT, CORRUPT):
            raise ValueError(f"a servo's fault is {ANSWERS}, {SILENT} or {CORRUPT}; got {fault!r}")
        self._fault[servo_id] = fault

    def clear(self) -> None:
        """Every fault cleared, mute included."""
        self.muted = False
        self._fault = dict.fromkeys(self._fault, ANSWERS)

    def states(self) -> dict[int, str]:
        """Each servo's reply state: "answers", "silent", "corrupt" or "muted"."""
        return {servo_id: MUTED if self.muted else fault for servo_id, fault in self._fault.items()}

    def reply(self, servos: list[Servo], reply_id: int, data: bytes) -> bytes:
        """The status packet `servos` (those at `reply_id`) send back: none if they are all silent or
        the bus is muted, garbled if two speak at once or the one speaking is corrupt."""
        if self.muted:
            return b""
        speaking = [servo for servo in servos if self._fault[servo.mechanics.servo_id] != SILENT]
        if not speaking:
            return b""
        garbled = len(speaking) > 1 or self._fault[speaking[0].mechanics.servo_id] == CORRUPT
        return status_packet(reply_id, data, garbled)
