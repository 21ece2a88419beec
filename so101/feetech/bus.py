"""The Feetech bus: Feetech's SDK (`scservo_sdk`, over pyserial) behind a few calls by register name.

Every failure becomes a BusError whose message is one line for the user: a port that
cannot be opened (NoPort), a servo that does not answer or answers garbage (ServoSilent,
naming its ID), or a port that went away mid-run (BusLost). The SDK signals those by
result codes and, for a vanished port, by pyserial exceptions; nothing else leaks out.
"""

from __future__ import annotations

import select
import termios
import time
from typing import Any

import scservo_sdk as scs
import serial

from so101.feetech.sts3215 import BAUD_RATE, REGISTERS

CHECK_SERVO = "check its power, its cable and that its ID is {servo_id}"


class BusError(Exception):
    """The bus failed; str() is one line naming what and what to check."""


class NoPort(BusError):
    pass


class BusLost(BusError):
    pass


class ServoSilent(BusError):
    def __init__(self, servo_id: int, corrupt: bool, what: str):
        self.servo_id = servo_id
        self.corrupt = corrupt
        problem = "sent a corrupted reply" if corrupt else "did not answer"
        super().__init__(f"servo {servo_id} {problem} to {what}: " + CHECK_SERVO.format(servo_id=servo_id))


class PortHandler(scs.PortHandler):  # the SDK is untyped
    """Feetech's PortHandler, with three holes closed, all opened by a loaded machine:
    - the SDK reads what has arrived, then asks whether the reply's time is up; descheduled between
      the two, it finds its time up with the reply waiting, and reports a servo that did answer as
      silent. Here the time is up only when nothing is waiting to be read;
    - a reply that comes after its request gave up stays in the port, and the SDK reads it as the
      next request's reply (a wrong value, or a cut-short packet it fails to index). Here what is
      waiting is thrown away before each request;
    - the SDK opens the port with timeout=0 and reads it in a loop until the reply is in: a driver
      waiting for a reply spins a core, likely taking it from the kernel's worker thread that hands
      bytes from the adapter (or a pseudo-terminal) to the reader, the very thing it waits for. With
      two such drivers (arm and leader) and two busy processes on 2 cores, the emulated servos'
      requests sat undelivered for up to 0.7 s (tools/under_load.py), and not once after this fix.
      Here a read waits in select() for the first byte, at most until the reply's time is up."""

    def readPort(self, length: int) -> bytes:
        if not self.ser.in_waiting:
            remaining_ms = self.packet_timeout - self.getTimeSinceStart()
            if remaining_ms > 0:
                select.select([self.ser.fd], [], [], remaining_ms / 1000)
        return self.ser.read(length)

    def clearPort(self) -> None:
        self.ser.reset_input_buffer()
        super().clearPort()

    def isPacketTimeout(self) -> bool:
        if self.ser.in_waiting:
            return False
        return bool(super().isPacketTimeout())


def _bytes(value: int, size: int) -> list[int]:
    return list(int(value).to_bytes(size, "little"))


class FeetechBus:
    """One serial port with STS3215 servos on it. `open()` first; `close()` is safe twice."""

    def __init__(self, port: str, baudrate: int = BAUD_RATE):
        self.port_name = port
        self.baudrate = baudrate
        # The SDK's PortHandler and PacketHandler (untyped); _port is None while the bus is closed.
        self._port: Any = None
        self._packets: Any = None
        self._readers: dict[tuple[str, tuple[int, ...]], scs.GroupSyncRead] = {}
        self.last_round_trip_s = 0.0  # of the last sync read: request out, every reply in

    def open(self) -> "FeetechBus":
        port = PortHandler(self.port_name)
        try:
            opened = port.openPort() and port.setBaudRate(self.baudrate)
        except (serial.SerialException, OSError) as error:
            raise NoPort(f"cannot open the serial port {self.port_name}: {_reason(error)}; "
                         "is the arm's USB adapter plugged in (so101 fake-arm emulates one)?") from None
        if not opened:
            raise NoPort(f"cannot set {self.port_name} to {self.baudrate} baud")
        self._port, self._packets = port, scs.PacketHandler(0)
        return self

    def close(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            try:
                port.closePort()
            except (serial.SerialException, OSError):
                pass

    def _call(self, function, *args):
        """One SDK call; a port that went away becomes BusLost."""
        if self._port is None:
            raise BusLost(f"the serial port {self.port_name} is closed")
        try:
            return function(*args)
        except (serial.SerialException, OSError, termios.error, TypeError, IndexError) as error:
            # termios.error: an unplugged adapter, from the SDK's flush(); TypeError/IndexError: the
            # SDK indexing a reply that a dying port cut short.
            raise BusLost(f"lost the serial port {self.port_name} ({_reason(error)}): "
                          "check the USB cable and the servos' power supply") from None
        finally:
            # The SDK marks the port busy during a transfer and leaves it so if one raises.
            self._port.is_using = False

    def ping(self, servo_id: int) -> int | None:
        """The servo's model number, or None if nothing answers at that ID."""
        model, result, _ = self._call(self._packets.ping, self._port, servo_id)
        return model if result == scs.COMM_SUCCESS else None

    def read(self, servo_id: int, name: str) -> int:
        address, size = REGISTERS[name]
        self._call(self._port.ser.reset_input_buffer)
        data, result, _ = self._call(self._packets.readTxRx, self._port, servo_id, address, size)
        if result != scs.COMM_SUCCESS:
            raise ServoSilent(servo_id, result == scs.COMM_RX_CORRUPT, f"a read of {name}")
        return int.from_bytes(bytes(data[:size]), "little")

    def write(self, servo_id: int, name: str, value: int) -> None:
        """A write the servo acknowledges."""
        address, size = REGISTERS[name]
        self._call(self._port.ser.reset_input_buffer)
        result, _ = self._call(self._packets.writeTxRx, self._port, servo_id, address, size, _bytes(value, size))
        if result != scs.COMM_SUCCESS:
            raise ServoSilent(servo_id, result == scs.COMM_RX_CORRUPT, f"a write of {name}")

    def sync_read(self, name: str, servo_ids: tuple[int, ...]) -> dict[int, int]:
        """One SYNC READ of `name` from every servo; ServoSilent names the first that failed."""
        address, size = REGISTERS[name]
        reader = self._readers.get((name, servo_ids))
        if reader is None:
            reader = self._readers[(name, servo_ids)] = scs.GroupSyncRead(self._port, self._packets, address, size)
            for servo_id in servo_ids:
                reader.addParam(servo_id)
        # A late reply to an earlier request must not pass for this one.
        self._call(self._port.ser.reset_input_buffer)
        start = time.perf_counter()
        result = self._call(reader.txRxPacket)
        self.last_round_trip_s = time.perf_counter() - start
        if result != scs.COMM_SUCCESS:
            # The SDK stops at the first servo that failed and leaves it without data.
            failed = next((i for i in servo_ids if len(reader.data_dict.get(i, [])) < size), servo_ids[0])
            raise ServoSilent(failed, result == scs.COMM_RX_CORRUPT, f"a sync read of {name}")
        return {servo_id: reader.getData(servo_id, address, size) for servo_id in servo_ids}

    def sync_write(self, name: str, values: dict[int, int]) -> None:
        """One SYNC WRITE (no reply: the servos cannot say whether they heard it)."""
        address, size = REGISTERS[name]
        writer = scs.GroupSyncWrite(self._port, self._packets, address, size)
        for servo_id, value in values.items():
            writer.addParam(servo_id, _bytes(value, size))
        if self._call(writer.txPacket) != scs.COMM_SUCCESS:
            raise BusLost(f"could not send to {self.port_name}: check the USB cable")


def _reason(error: Exception) -> str:
    text = getattr(error, "strerror", None) or str(error) or type(error).__name__
    return " ".join(text.split())
