"""The wire: Feetech's serial protocol ("protocol 0", the one `scservo_sdk.PacketHandler(0)` speaks),
as the emulated bus reads and answers it.

    instruction  FF FF ID LEN INSTR PARAM... CHK     LEN = len(PARAM) + 2
    status       FF FF ID LEN ERR   PARAM... CHK     CHK = ~(ID + LEN + INSTR/ERR + sum(PARAM)) & 0xFF

PING 0x01, READ 0x02 (address, length), WRITE 0x03 (address, data...), REG_WRITE 0x04 +
ACTION 0x05 (a write held until ACTION), SYNC_READ 0x82 (to the broadcast ID 0xFE: address,
length, id1, id2, ...; each listed servo answers with its own status packet, in the listed
order) and SYNC_WRITE 0x83 (broadcast: address, length, then id + length bytes per servo; no
answer). A packet with a bad checksum is ignored and the byte stream is resynchronised on FF FF
(a packet may arrive in pieces; one left incomplete for PARTIAL_PACKET_TIMEOUT_S is dropped).
"""

from __future__ import annotations

from dataclasses import dataclass, field

HEADER = b"\xff\xff"
BROADCAST_ID = 0xFE
PING, READ, WRITE, REG_WRITE, ACTION = 0x01, 0x02, 0x03, 0x04, 0x05
SYNC_READ, SYNC_WRITE = 0x82, 0x83
# A packet whose remaining bytes do not come within this time is dropped (at 1,000,000 baud
# a whole 250-byte packet takes 2.5 ms; a client writes a packet in one go).
PARTIAL_PACKET_TIMEOUT_S = 0.05


def checksum(body: bytes) -> int:
    """The checksum of a packet's ID, LEN, INSTR/ERR and parameters."""
    return ~sum(body) & 0xFF


def instruction_packet(servo_id: int, instruction: int, params: bytes = b"") -> bytes:
    """An instruction packet, as a host sends it (for tests and tools that bypass the SDK)."""
    body = bytes([servo_id, len(params) + 2, instruction]) + bytes(params)
    return HEADER + body + bytes([checksum(body)])


def status_packet(reply_id: int, data: bytes, garbled: bool = False) -> bytes:
    """A servo's status packet (error byte 0); `garbled` gives it a wrong checksum, as two servos
    answering at once, or a corrupted line, do."""
    body = bytes([reply_id, len(data) + 2, 0]) + data
    check = checksum(body)
    return HEADER + body + bytes([check ^ 0xFF if garbled else check])


@dataclass(frozen=True)
class Instruction:
    """One instruction packet with a good checksum: its target ID, instruction and parameters."""

    target: int
    instruction: int
    params: bytes


@dataclass
class PacketReader:
    """Cuts the bytes a host writes into instruction packets, as a servo's receiver does."""

    buffer: bytearray = field(default_factory=bytearray)
    bad_checksums: int = 0
    dropped_bytes: int = 0

    @property
    def waiting(self) -> bool:
        """Part of a packet is held, waiting for the rest."""
        return bool(self.buffer)

    def drop_partial(self) -> None:
        """A partial packet that was never finished: drop it, look for the next header."""
        following = self.buffer.find(HEADER, 1)
        cut = following if following > 0 else len(self.buffer)
        self.dropped_bytes += cut
        del self.buffer[:cut]

    def feed(self, data: bytes) -> list[Instruction]:
        """Take `data`; return every instruction packet now complete, in order."""
        buffer = self.buffer
        buffer += data
        packets = []
        while True:
            start = buffer.find(HEADER)
            if start < 0:
                keep = 1 if buffer[-1:] == b"\xff" else 0
                self.dropped_bytes += len(buffer) - keep
                del buffer[: len(buffer) - keep]
                break
            if start:
                self.dropped_bytes += start
                del buffer[:start]
            if len(buffer) < 4:
                break
            if buffer[2] == 0xFF:  # FF FF FF: the header is the later pair
                self.dropped_bytes += 1
                del buffer[0]
                continue
            length = buffer[3]
            if length < 2:
                self.dropped_bytes += 2
                del buffer[:2]
                continue
            total = length + 4
            if len(buffer) < total:
                break
            packet = bytes(buffer[:total])
            if checksum(packet[2:-1]) != packet[-1]:
                self.bad_checksums += 1
                del buffer[:2]  # resynchronise on the next FF FF
                continue
            del buffer[:total]
            packets.append(Instruction(packet[2], packet[4], packet[5:-1]))
        return packets
