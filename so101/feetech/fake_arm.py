"""An emulated SO-101 servo bus on a pseudo-terminal (`so101 fake-arm`, so101/cli/fake_arm.py).

Six Feetech STS3215 servos (IDs 1-6) answer Feetech's serial protocol ("protocol 0", the
one `scservo_sdk.PacketHandler(0)` speaks) on a pseudo-terminal such as /dev/pts/7, so the
real-arm driver, `so101 calibrate` and their tests run without hardware. It emulates the
protocol, the register table (so101/feetech/sts3215.py) and an assembled arm's hard stops; it is not
a physics model: no gravity, no load, no inertia, a constant speed.

The protocol, from Feetech's published description:

    instruction  FF FF ID LEN INSTR PARAM... CHK     LEN = len(PARAM) + 2
    status       FF FF ID LEN ERR   PARAM... CHK     CHK = ~(ID + LEN + INSTR/ERR + sum(PARAM)) & 0xFF

PING 0x01, READ 0x02 (address, length), WRITE 0x03 (address, data...), REG_WRITE 0x04 +
ACTION 0x05 (a write held until ACTION), SYNC_READ 0x82 (to the broadcast ID 0xFE: address,
length, id1, id2, ...; each listed servo answers with its own status packet, in the listed
order) and SYNC_WRITE 0x83 (broadcast: address, length, then id + length bytes per servo; no
answer). As on a real bus: a packet with a bad checksum is ignored, broadcast instructions
(other than SYNC_READ) get no answer, an ID that is not on the bus gets no answer, and the
byte stream is resynchronised on FF FF (a packet may arrive in pieces; one left incomplete
for PARTIAL_PACKET_TIMEOUT_S is dropped).

Positions, as the STS3215 does them (all in encoder steps, 4096 per turn):
    Present_Position = (physical - Homing_Offset) mod 4096     (Homing_Offset: sign bit 11)
    Goal_Position g  -> the servo drives its Present_Position to g, clamped to
                        [Min_Position_Limit, Max_Position_Limit] unless both are 0
With Torque_Enable = 1 the motor moves toward the goal at a constant speed (Goal_Velocity if
not 0, capped at the motor's speed) without crossing the 0/4095 seam of its own (offset)
frame, as a servo in position mode does; the hard stops stop it. The motion is computed
lazily from time.monotonic() whenever a register is read or written, so it is exact however
often, or seldom, the bus is polled. Torque_Enable = 0: the motor does not move by itself,
but a hand can move it (`move_by_hand`, `sweep`, and `play_hand`, which plays a script of
angles such as so101/feetech/hand.py's figure eight: the emulator then plays a leader arm).
Writing 128 to Torque_Enable sets Homing_Offset so that the current position reads 2048
(Feetech's "middle position calibration"). Only position mode (Operating_Mode 0) is
emulated; Goal_Time and Acceleration are stored but not emulated (the speed is constant, a
new goal takes effect at once). `values_written` lists what the bus wrote to a register.

EEPROM (addresses below 40) behaves as Feetech describes the Lock register: a write takes
effect at once; it is kept through `power_cycle()` only if it was made with Lock = 0. A servo
whose Baud_Rate register is set to anything but 0 (1,000,000 baud) no longer hears the bus,
as a real one listening at another speed. A write to ID moves the servo to its new ID (it
answers that write from the old one). Two servos that answer at once collide: the host gets
one packet with a wrong checksum.

A host that resets the first servo's Homing_Offset to 0 with torque off is starting a calibration:
`on_calibration` is called then (`so101 fake-arm` tells the person to type `sweep`).
"""

from __future__ import annotations

import math
import os
import select
import threading
import time
import tty
from dataclasses import dataclass
from typing import Callable, Sequence

from so101.feetech import sts3215
from so101.feetech.hand import eased_in
from so101.robot import ACTUATED_JOINTS, GRIPPER_COMMAND_INDEX, goal_deg

# -- the protocol ------------------------------------------------------------------------

HEADER = b"\xff\xff"
BROADCAST_ID = 0xFE
PING, READ, WRITE, REG_WRITE, ACTION = 0x01, 0x02, 0x03, 0x04, 0x05
SYNC_READ, SYNC_WRITE = 0x82, 0x83
MEMORY_SIZE = 256  # the register memory, addresses 0-255; a READ past its end gets no answer
# A packet whose remaining bytes do not come within this time is dropped (at 1,000,000 baud
# a whole 250-byte packet takes 2.5 ms; a client writes a packet in one go).
PARTIAL_PACKET_TIMEOUT_S = 0.05

_ADDRESS = {name: address for name, (address, _) in sts3215.REGISTERS.items()}
# Addresses 0-4 (firmware version, Model_Number) and everything from Present_Position on are
# the servo's to write; a host's write to them is ignored, as by a real servo.
FIRST_WRITABLE = _ADDRESS["ID"]
FIRST_READ_ONLY = _ADDRESS["Present_Position"]
CALIBRATE_MIDDLE = 128  # written to Torque_Enable: the current position becomes 2048
MIDDLE = sts3215.STEPS_PER_TURN // 2
BAUD_INDEX_1M = 0  # Baud_Rate register value for 1,000,000 baud: the bus this emulates

# The motor's top speed with Goal_Velocity = 0, in steps/s: 3000 steps/s ≈ 264°/s, near an
# STS3215's no-load speed at 7.4 V (0.222 s per 60°, ≈ 270°/s). Load would slow a real one.
DEFAULT_SPEED_STEPS_S = 3000.0
SUPPLY_DECIVOLTS = 120  # Present_Voltage: 12.0 V
TEMPERATURE_C = 30  # Present_Temperature

# What each servo holds at power-up (all other addresses 0). Goal_Position = the present
# position and the read-only registers are filled in from the physical state.
POWER_UP: dict[str, int] = {
    "Model_Number": sts3215.MODEL_NUMBER,
    "Baud_Rate": BAUD_INDEX_1M,
    "Return_Delay_Time": 0,
    "Min_Position_Limit": 0,
    "Max_Position_Limit": sts3215.MAX_STEP,
    "Max_Torque_Limit": 1000,
    "P_Coefficient": 32,
    "D_Coefficient": 32,
    "I_Coefficient": 0,
    "Homing_Offset": 0,
    "Operating_Mode": 0,
    "Torque_Enable": 0,
    "Acceleration": 0,
    "Goal_Time": 0,
    "Goal_Velocity": 0,
    "Torque_Limit": 1000,
    "Lock": 1,
}


def checksum(body: bytes) -> int:
    """The checksum of a packet's ID, LEN, INSTR/ERR and parameters."""
    return ~sum(body) & 0xFF


def instruction_packet(servo_id: int, instruction: int, params: bytes = b"") -> bytes:
    """An instruction packet, as a host sends it (for tests and tools that bypass the SDK)."""
    body = bytes([servo_id, len(params) + 2, instruction]) + bytes(params)
    return HEADER + body + bytes([checksum(body)])


# -- the assembled arm ----------------------------------------------------------------------

# The mechanical model, one row per servo: (ID, joint, assembly offset, hard stops?).
# The assembly offset is where the middle of the joint's travel lands on the servo's encoder,
# relative to 2048: a servo horn is never fitted exactly at mid-scale, so a calibration has real
# homing offsets to find (distinct, some negative, a few hundred steps). Joints with hard stops
# travel over their URDF range (so101/robot.py, converted at 4096 steps per 360°) centred on
# that middle; wrist_roll has no stops (it turns fully, its encoder wrapping 0..4095); the
# gripper's travel is its URDF span (-10° to 100°: 110°). At power-up every joint rests at its
# middle. No joint's travel crosses its encoder's 0/4095 seam.
MECHANICAL_TABLE: tuple[tuple[int, str, int, bool], ...] = (
    (1, "shoulder_pan", +310, True),
    (2, "shoulder_lift", -420, True),
    (3, "elbow_flex", +190, True),
    (4, "wrist_flex", -275, True),
    (5, "wrist_roll", +530, False),
    (6, "gripper", -360, True),
)


@dataclass(frozen=True)
class Mechanics:
    """One joint as assembled: physical encoder positions (steps) of its middle and stops."""

    servo_id: int
    joint: str
    centre: int
    lower: int | None  # hard stops; None for a joint that turns fully
    upper: int | None

    @property
    def has_stops(self) -> bool:
        return self.stops is not None

    @property
    def stops(self) -> tuple[int, int] | None:
        """The hard stops (lower, upper) in physical steps; None for a joint that turns fully."""
        return None if self.lower is None or self.upper is None else (self.lower, self.upper)

    def clamp(self, physical: float) -> float:
        """Where the joint can be: inside its stops, or on its encoder's turn."""
        if self.stops is None:
            return physical % sts3215.STEPS_PER_TURN
        lower, upper = self.stops
        return min(max(physical, lower), upper)


def _mechanics() -> dict[int, Mechanics]:
    by_name = {joint.name: joint for joint in ACTUATED_JOINTS}
    table = {}
    for servo_id, name, offset, has_stops in MECHANICAL_TABLE:
        centre = MIDDLE + offset
        lower = upper = None
        if has_stops:
            joint = by_name[name]
            half = round((joint.upper_deg - joint.lower_deg) / 360.0 * sts3215.STEPS_PER_TURN / 2)
            lower, upper = centre - half, centre + half
        table[servo_id] = Mechanics(servo_id, name, centre, lower, upper)
    return table


MECHANICS: dict[int, Mechanics] = _mechanics()
ALL_IDS = tuple(MECHANICS)
STEPS_PER_DEG = sts3215.STEPS_PER_TURN / 360.0
_GRIPPER = ACTUATED_JOINTS[GRIPPER_COMMAND_INDEX]


# -- degrees, as the factory-calibrated arm reads them (calibrate_as_at_the_factory) --------------


def _script_steps(mechanics: Mechanics, angle_deg: float) -> float:
    """`angle_deg` in physical steps, held inside the stops; a joint without stops is not wrapped
    (a hand turning it past its encoder's seam moves on smoothly, in steps/s)."""
    if mechanics.joint == _GRIPPER.name and mechanics.stops is not None:
        lower, upper = mechanics.stops
        fraction = (angle_deg - _GRIPPER.lower_deg) / (_GRIPPER.upper_deg - _GRIPPER.lower_deg)
        steps = lower + fraction * (upper - lower)
    else:
        steps = mechanics.centre + angle_deg * STEPS_PER_DEG
    return steps if mechanics.stops is None else mechanics.clamp(steps)


def physical_steps(mechanics: Mechanics, angle_deg: float) -> float:
    """Where a joint at `angle_deg` stands on its encoder (physical steps, before any homing offset),
    clamped into its stops (wrist_roll, without stops, on its turn 0..4096). The degrees are what the
    arm calibrated as at the factory reads (so101/feetech/calibration.py steps_to_deg): joints 1-5 0° at
    the middle of their travel, 360° a turn; the gripper the URDF's -10°..100° across its stops."""
    return mechanics.clamp(_script_steps(mechanics, angle_deg))


def joint_deg(mechanics: Mechanics, physical: float) -> float:
    """The inverse of physical_steps: the angle of a joint standing at `physical` steps (wrist_roll
    from -180° to 180°)."""
    if mechanics.joint == _GRIPPER.name and mechanics.stops is not None:
        lower, upper = mechanics.stops
        return _GRIPPER.lower_deg + (physical - lower) / (upper - lower) * (_GRIPPER.upper_deg - _GRIPPER.lower_deg)
    from_centre = physical - mechanics.centre
    if mechanics.stops is None:
        from_centre = (from_centre + MIDDLE) % sts3215.STEPS_PER_TURN - MIDDLE
    return from_centre / STEPS_PER_DEG


# `sweep`: how long the hand rests on each stop, as a share of the whole sweep.
SWEEP_DWELL_SHARE = 0.1
# A scripted hand's Present_Velocity: the change of position over this much time either side.
VELOCITY_SPAN_S = 0.001


class _HandPath:
    """A hand moving a joint: straight lines between (time, unwrapped physical position) points."""

    def __init__(self, points: list[tuple[float, float]]):
        self.points = points

    @property
    def end_time(self) -> float:
        return self.points[-1][0]

    def at(self, now: float) -> tuple[float, float]:
        """(position, velocity in steps/s) at `now`."""
        if now >= self.end_time:
            return self.points[-1][1], 0.0
        if now <= self.points[0][0]:
            return self.points[0][1], 0.0
        for (t0, p0), (t1, p1) in zip(self.points, self.points[1:]):
            if now < t1:
                slope = (p1 - p0) / (t1 - t0) if t1 > t0 else 0.0
                return p0 + slope * (now - t0), slope
        return self.points[-1][1], 0.0


class _ScriptedHand:
    """A hand moving one joint along a script of six angles in degrees (FakeArm.play_hand),
    from `start` (time.monotonic) for `duration_s` (None: until it is stopped)."""

    def __init__(self, script: Callable[[float], Sequence[float]], mechanics: Mechanics, start: float,
                 duration_s: float | None):
        self.script = script
        self.mechanics = mechanics
        self.index = mechanics.servo_id - 1
        self.start = start
        self.duration_s = duration_s

    @property
    def end_time(self) -> float:
        return math.inf if self.duration_s is None else self.start + self.duration_s

    def _steps(self, t_s: float) -> float:
        return _script_steps(self.mechanics, float(self.script(t_s)[self.index]))

    def at(self, now: float) -> tuple[float, float]:
        """(position, velocity in steps/s) at `now`; the velocity by a central difference."""
        t_s = max(0.0, now - self.start)
        if self.duration_s is not None and t_s >= self.duration_s:
            return self._steps(self.duration_s), 0.0
        before = max(0.0, t_s - VELOCITY_SPAN_S)
        after = t_s + VELOCITY_SPAN_S
        if self.duration_s is not None:
            after = min(after, self.duration_s)
        return self._steps(t_s), (self._steps(after) - self._steps(before)) / (after - before)


class _Servo:
    """One STS3215: its register memory and the physical position of its joint."""

    def __init__(self, mechanics: Mechanics, physical: float, now: float):
        self.mechanics = mechanics
        self.memory = bytearray(MEMORY_SIZE)
        self.physical = float(physical)  # encoder steps, inside the stops (or 0..4096 without)
        self.velocity = 0.0  # steps/s at self.time
        self.time = now
        self.hand: _HandPath | _ScriptedHand | None = None
        # Every value the bus wrote, by register (FakeArm.values_written).
        self.written: dict[str, set[int]] = {name: set() for name in sts3215.REGISTERS}
        self.pending: tuple[int, bytes] | None = None  # REG_WRITE, until ACTION
        self.fault = ""  # "", "silent" or "corrupt"
        for name, value in POWER_UP.items():
            self.set(name, value)
        self.set("ID", mechanics.servo_id)
        self.saved_eeprom = bytes(self.memory[: sts3215.EEPROM_END])
        self.power_up_ram()

    # registers, raw (as stored)
    def get(self, name: str) -> int:
        address, size = sts3215.REGISTERS[name]
        return int.from_bytes(self.memory[address : address + size], "little")

    def set(self, name: str, raw: int) -> None:
        address, size = sts3215.REGISTERS[name]
        self.memory[address : address + size] = (raw & ((1 << (8 * size)) - 1)).to_bytes(size, "little")

    def power_up_ram(self) -> None:
        ram = sts3215.EEPROM_END
        self.memory[ram:] = bytes(MEMORY_SIZE - ram)
        for name, value in POWER_UP.items():
            if sts3215.REGISTERS[name][0] >= ram:
                self.set(name, value)
        self.velocity = 0.0
        self.pending = None
        self.refresh()
        self.set("Goal_Position", self.get("Present_Position"))

    @property
    def bus_id(self) -> int:
        return self.get("ID")

    @property
    def hears_bus(self) -> bool:
        return self.get("Baud_Rate") == BAUD_INDEX_1M

    @property
    def torque_on(self) -> bool:
        return self.get("Torque_Enable") != 0

    @property
    def homing_offset(self) -> int:
        return sts3215.decode_signed(self.get("Homing_Offset"), sts3215.SIGN_BITS["Homing_Offset"])

    def goal(self) -> int:
        """The position the motor drives to, in the offset frame, after the limits."""
        goal = sts3215.decode_signed(self.get("Goal_Position"), 15)
        low, high = self.get("Min_Position_Limit"), self.get("Max_Position_Limit")
        if low == 0 and high == 0:
            # No limits: the STS3215's multi-turn use. Approximated: goals past 0..4095 add turns.
            return goal
        return min(max(goal, low), high)

    def speed(self, top_speed: float) -> float:
        asked = abs(sts3215.decode_signed(self.get("Goal_Velocity"), sts3215.SIGN_BITS["Goal_Velocity"]))
        return min(float(asked), top_speed) if asked else top_speed

    def advance(self, now: float, top_speed: float) -> None:
        """Bring the joint to `now`: the hand's path, or the motor toward its goal."""
        elapsed = max(0.0, now - self.time)
        self.time = max(self.time, now)
        if self.hand is not None and not self.torque_on:
            position, self.velocity = self.hand.at(now)
            self.physical = self.mechanics.clamp(position)
            if now >= self.hand.end_time:
                self.hand = None
        elif self.torque_on:
            self.hand = None
            present = (self.physical - self.homing_offset) % sts3215.STEPS_PER_TURN
            error = self.goal() - present
            speed = self.speed(top_speed)
            direction = 1.0 if error > 0 else -1.0
            travel = min(abs(error), speed * elapsed)
            arrived = travel >= abs(error)
            wanted = self.physical + (error if arrived else direction * travel)
            self.physical = self.mechanics.clamp(wanted)
            blocked = self.mechanics.has_stops and self.physical != wanted
            self.velocity = 0.0 if arrived or blocked else direction * speed
        else:
            self.velocity = 0.0
        self.refresh()

    def refresh(self) -> None:
        """The registers the servo writes itself, from the physical state."""
        self.set("Present_Position", (round(self.physical) - self.homing_offset) % sts3215.STEPS_PER_TURN)
        speed = min(round(abs(self.velocity)), (1 << 15) - 1)
        self.set("Present_Velocity", sts3215.encode_signed(speed if self.velocity >= 0 else -speed, 15))
        self.set("Moving", 1 if self.velocity else 0)
        self.set("Present_Load", 0)
        self.set("Present_Current", 0)
        self.set("Present_Voltage", SUPPLY_DECIVOLTS)
        self.set("Present_Temperature", TEMPERATURE_C)

    def write(self, address: int, data: bytes) -> None:
        """A host's write, byte by byte as the servo takes it (call advance() first)."""
        torque_address = _ADDRESS["Torque_Enable"]
        for index, value in enumerate(data):
            where = address + index
            if where >= MEMORY_SIZE:
                break
            if not FIRST_WRITABLE <= where < FIRST_READ_ONLY:
                continue
            if where == torque_address and value == CALIBRATE_MIDDLE:
                self.calibrate_middle()
                continue
            self.memory[where] = value
            if where < sts3215.EEPROM_END and self.get("Lock") == 0:
                self.saved_eeprom = self.saved_eeprom[:where] + bytes([value]) + self.saved_eeprom[where + 1 :]
        if self.torque_on:
            self.hand = None  # the motor holds: a hand cannot move it
        elif self.hand is None:
            self.velocity = 0.0
        self.refresh()

    def host_write(self, address: int, data: bytes) -> dict[str, int]:
        """A write that came over the bus: logged for values_written, then taken as write() does.
        Returns the registers it covers whole, with the values sent (signed ones decoded)."""
        end = address + len(data)
        sent = {}
        for name, (start, size) in sts3215.REGISTERS.items():
            if address <= start and start + size <= end:
                raw = int.from_bytes(data[start - address : start - address + size], "little")
                bit = sts3215.SIGN_BITS.get(name)
                sent[name] = sts3215.decode_signed(raw, bit) if bit is not None else raw
                self.written[name].add(sent[name])
        self.write(address, data)
        return sent

    def calibrate_middle(self) -> None:
        bit = sts3215.SIGN_BITS["Homing_Offset"]
        limit = (1 << bit) - 1
        offset = max(-limit, min(limit, round(self.physical) % sts3215.STEPS_PER_TURN - MIDDLE))
        self.set("Homing_Offset", sts3215.encode_signed(offset, bit))
        address, size = sts3215.REGISTERS["Homing_Offset"]
        saved = bytearray(self.saved_eeprom)
        saved[address : address + size] = self.memory[address : address + size]
        self.saved_eeprom = bytes(saved)


# -- the emulator ----------------------------------------------------------------------------


class FakeArm:
    """Six emulated STS3215 servos on a pseudo-terminal; `.port` is the path a driver opens.

        with FakeArm() as arm:
            port = PortHandler(arm.port)   # scservo_sdk, as for a real arm

    `servo_id` in this API is a servo's power-up ID (its joint, 1-6), whatever its ID register
    says later. Registers are read and written by name (so101/feetech/sts3215.py), signed ones as
    signed numbers. All methods are safe to call from any thread.
    """

    def __init__(
        self,
        ids: tuple[int, ...] | list[int] = ALL_IDS,
        speed_steps_s: float = DEFAULT_SPEED_STEPS_S,
        start_positions: dict[int, int] | None = None,
    ):
        ids = tuple(ids)
        unknown = [servo_id for servo_id in ids if servo_id not in MECHANICS]
        if unknown or not ids or len(set(ids)) != len(ids):
            raise ValueError(f"servo ids must be distinct, from {ALL_IDS[0]} to {ALL_IDS[-1]}; got {ids}")
        if not speed_steps_s > 0:
            raise ValueError(f"speed_steps_s must be positive, got {speed_steps_s}")
        start_positions = dict(start_positions or {})
        for servo_id, position in start_positions.items():
            mechanics = MECHANICS.get(servo_id)
            if servo_id not in ids or mechanics is None:
                raise ValueError(f"start_positions names servo {servo_id}, which is not on this bus ({ids})")
            low, high = mechanics.stops or (0, sts3215.MAX_STEP)
            if not low <= position <= high:
                raise ValueError(
                    f"start position {position} of servo {servo_id} ({mechanics.joint}) is outside "
                    f"its travel, {low}..{high} steps"
                )
        self.speed_steps_s = float(speed_steps_s)
        self._lock = threading.RLock()
        now = time.monotonic()
        self._servos = {
            servo_id: _Servo(MECHANICS[servo_id], start_positions.get(servo_id, MECHANICS[servo_id].centre), now)
            for servo_id in ids
        }
        self._muted = False
        self._counts = {"packets": 0, "replies": 0, "bad_checksums": 0, "dropped_bytes": 0}
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.port = os.ttyname(self._slave)
        self._wake_read, self._wake_write = os.pipe()
        self._thread: threading.Thread | None = None
        self._port_open = True
        self._buffer = bytearray()
        # Called (from the bus thread, so briefly) when a host starts a calibration; see _host_wrote.
        self.on_calibration: Callable[[], None] | None = None

    # -- life cycle

    def start(self) -> "FakeArm":
        """Start serving the bus (a daemon thread). Returns self."""
        with self._lock:
            if self._thread is None and self._port_open:
                self._thread = threading.Thread(target=self._serve, name="fake-arm-bus", daemon=True)
                self._thread.start()
        return self

    def close_port(self) -> None:
        """The pseudo-terminal goes away, as an unplugged USB adapter: the client's next read
        or write fails and the path no longer exists. The servos stay readable here."""
        with self._lock:
            if not self._port_open:
                return
            self._port_open = False
            thread, self._thread = self._thread, None
        os.write(self._wake_write, b"x")
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=2.0)
        for fd in (self._master, self._slave, self._wake_read, self._wake_write):
            try:
                os.close(fd)
            except OSError:
                pass

    def close(self) -> None:
        """Stop serving and release the pseudo-terminal; safe to call twice."""
        self.close_port()

    def __enter__(self) -> "FakeArm":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def port_open(self) -> bool:
        return self._port_open

    @property
    def ids(self) -> tuple[int, ...]:
        return tuple(self._servos)

    @property
    def packets_served(self) -> int:
        """Instruction packets received with a good checksum (to any ID), since the start."""
        return self._counts["packets"]

    def stats(self) -> dict[str, int]:
        """Counters: packets (good ones received), replies (status packets sent),
        bad_checksums (packets ignored), dropped_bytes (noise and stale partial packets)."""
        with self._lock:
            return dict(self._counts)

    # -- registers and the joint, for tests and tools

    def _servo(self, servo_id: int) -> _Servo:
        try:
            return self._servos[servo_id]
        except KeyError:
            raise ValueError(f"no servo {servo_id} on this bus; ids: {self.ids}") from None

    def read_register(self, servo_id: int, name: str) -> int:
        """A register's value now (signed registers decoded)."""
        if name not in sts3215.REGISTERS:
            raise KeyError(f"no register {name!r}; see so101/feetech/sts3215.py")
        with self._lock:
            servo = self._servo(servo_id)
            servo.advance(time.monotonic(), self.speed_steps_s)
            raw = servo.get(name)
        bit = sts3215.SIGN_BITS.get(name)
        return sts3215.decode_signed(raw, bit) if bit is not None else raw

    def write_register(self, servo_id: int, name: str, value: int) -> None:
        """Write a register as a host's WRITE would (same rules: EEPROM and Lock, 128 to
        Torque_Enable, ...), but whatever the faults. ValueError for a read-only register."""
        if name not in sts3215.REGISTERS:
            raise KeyError(f"no register {name!r}; see so101/feetech/sts3215.py")
        address, size = sts3215.REGISTERS[name]
        if not FIRST_WRITABLE <= address < FIRST_READ_ONLY:
            raise ValueError(f"{name} is read-only: the servo writes it")
        bit = sts3215.SIGN_BITS.get(name)
        raw = sts3215.encode_signed(value, bit) if bit is not None else int(value)
        if not 0 <= raw < 1 << (8 * size):
            raise ValueError(f"{value} does not fit {name} ({size} byte{'s' if size > 1 else ''})")
        with self._lock:
            servo = self._servo(servo_id)
            servo.advance(time.monotonic(), self.speed_steps_s)
            servo.write(address, raw.to_bytes(size, "little"))

    def values_written(self, servo_id: int, name: str) -> frozenset[int]:
        """Every value the bus (WRITE, REG_WRITE then ACTION, SYNC_WRITE) ever wrote to this register of
        servo `servo_id`, as sent, whether or not the servo kept it (signed registers decoded); a write
        counts for each register it covers whole. Not write_register's: those are the test's own."""
        if name not in sts3215.REGISTERS:
            raise KeyError(f"no register {name!r}; see so101/feetech/sts3215.py")
        with self._lock:
            return frozenset(self._servo(servo_id).written[name])

    def physical_position(self, servo_id: int) -> int:
        """The joint's encoder reading before the homing offset (steps, 0..4095)."""
        with self._lock:
            servo = self._servo(servo_id)
            servo.advance(time.monotonic(), self.speed_steps_s)
            return round(servo.physical) % sts3215.STEPS_PER_TURN

    def joint_angle_deg(self, servo_id: int) -> float:
        """The joint's angle in degrees as the arm calibrated at the factory reads it (joint_deg)."""
        with self._lock:
            servo = self._servo(servo_id)
            servo.advance(time.monotonic(), self.speed_steps_s)
            return joint_deg(servo.mechanics, servo.physical)

    def mechanics(self, servo_id: int) -> Mechanics:
        """The joint's middle and hard stops (physical steps)."""
        return self._servo(servo_id).mechanics

    def power_cycle(self) -> None:
        """Power off and on: EEPROM back to what was saved (written with Lock = 0), RAM to its
        power-up values (torque off, Goal_Position = present, Lock = 1). The joints stay put."""
        with self._lock:
            now = time.monotonic()
            for servo in self._servos.values():
                servo.advance(now, self.speed_steps_s)
                servo.hand = None
                servo.memory[: sts3215.EEPROM_END] = servo.saved_eeprom
                servo.power_up_ram()

    # -- a hand

    def move_by_hand(self, servo_id: int, physical_steps: int, relative: bool = False) -> int:
        """Move a joint by hand to a physical encoder position (or by `physical_steps` with
        relative=True), stopped by its hard stops; returns where it is. With torque on the
        servo holds its position against the hand (modelled as perfectly stiff): nothing moves."""
        with self._lock:
            servo = self._servo(servo_id)
            servo.advance(time.monotonic(), self.speed_steps_s)
            if not servo.torque_on:
                servo.hand = None
                target = servo.physical + physical_steps if relative else float(physical_steps)
                servo.physical = servo.mechanics.clamp(round(target))
                servo.velocity = 0.0
                servo.refresh()
            return round(servo.physical) % sts3215.STEPS_PER_TURN

    def sweep(self, duration_s: float = 4.0, ids: tuple[int, ...] | None = None) -> tuple[int, ...]:
        """A person calibrating: over `duration_s`, every torque-off joint (of `ids`) moves from
        where it is to one stop, rests there, goes to the other stop, rests, and comes back to
        its middle; wrist_roll, which has no stops, turns half a turn each way from its middle
        (a full turn). Returns at once with the ids it moves; the motion happens in the background
        (evaluated from the clock as the motor's is). A joint whose torque is turned on stops
        following the hand. `wait_hand()` waits for the end."""
        if not duration_s > 0:
            raise ValueError(f"duration_s must be positive, got {duration_s}")
        swept = []
        with self._lock:
            now = time.monotonic()
            for servo_id in ids if ids is not None else self.ids:
                servo = self._servo(servo_id)
                servo.advance(now, self.speed_steps_s)
                if servo.torque_on:
                    continue
                swept.append(servo_id)
                servo.hand = _HandPath(self._sweep_points(servo, now, duration_s))
        return tuple(swept)

    @staticmethod
    def _sweep_points(servo: _Servo, now: float, duration_s: float) -> list[tuple[float, float]]:
        m = servo.mechanics
        start = servo.physical
        if m.stops is not None:
            lower, upper = (float(stop) for stop in m.stops)
        else:  # unwrap around the middle: the hand turns it 180° each way
            turn = sts3215.STEPS_PER_TURN
            start = m.centre + ((start - m.centre + MIDDLE) % turn - MIDDLE)
            lower, upper = float(m.centre - MIDDLE), float(m.centre + MIDDLE)
        dwell = SWEEP_DWELL_SHARE * duration_s
        legs = (abs(lower - start), upper - lower, abs(upper - m.centre))
        moving = duration_s - 2 * dwell
        per_step = moving / sum(legs)
        t = now
        points = [(t, start)]
        t += legs[0] * per_step
        points.append((t, lower))
        t += dwell
        points.append((t, lower))
        t += legs[1] * per_step
        points.append((t, upper))
        t += dwell
        points.append((t, upper))
        points.append((now + duration_s, float(m.centre)))
        return points

    def play_hand(
        self,
        angles_at: Callable[[float], Sequence[float]],
        duration_s: float | None = None,
        ease_s: float = 0.0,
        ids: tuple[int, ...] | None = None,
    ) -> tuple[int, ...]:
        """A hand moves every torque-off joint (of `ids`) along a script: `angles_at(t_s)` gives the six
        angles in degrees (so101/feetech/hand.py; physical_steps places them) `t_s` seconds from now,
        for `duration_s` (None: until stop_hand or another hand), the joints then left at the script's
        last angles. Over the first `ease_s` seconds the hand eases from where the joints stand into
        the script (hand.eased_in); with ease_s = 0 it takes them where the script starts at once.
        Returns at once with the ids it moves; the motion is evaluated from the clock, as the motor's
        is, so it is exact however often the bus is read. A joint whose torque is (or is turned) on
        does not follow. ValueError for a script that does not give six finite angles."""
        if duration_s is not None and not duration_s >= 0:
            raise ValueError(f"duration_s must be 0 or more (or None: until stopped), got {duration_s}")
        goal_deg(angles_at(0.0))  # six finite angles, or ValueError here rather than in the bus thread
        moved = []
        with self._lock:
            now = time.monotonic()
            for servo in self._servos.values():
                servo.advance(now, self.speed_steps_s)
            # The script sees all six joints; one not on this bus stays at 0°.
            start_deg = [0.0] * len(ACTUATED_JOINTS)
            for servo_id, servo in self._servos.items():
                start_deg[servo_id - 1] = joint_deg(servo.mechanics, servo.physical)
            script = eased_in(angles_at, start_deg, ease_s)
            chosen = [(servo_id, self._servo(servo_id)) for servo_id in (ids if ids is not None else self.ids)]
            for servo_id, servo in chosen:
                if servo.torque_on:
                    continue
                moved.append(servo_id)
                servo.hand = _ScriptedHand(script, servo.mechanics, now, duration_s)
        return tuple(moved)

    def stop_hand(self) -> tuple[int, ...]:
        """The hand lets go (a sweep or a script): every joint stays where it is. Returns the ids it
        was still moving."""
        let_go = []
        with self._lock:
            now = time.monotonic()
            for servo_id, servo in self._servos.items():
                servo.advance(now, self.speed_steps_s)  # a hand that has ended is gone after this
                if servo.hand is not None:
                    let_go.append(servo_id)
                    servo.hand = None
                    servo.velocity = 0.0
                    servo.refresh()
        return tuple(let_go)

    def hand_busy(self) -> bool:
        """Whether a hand (a sweep or a script) is still moving some joint; a script without a
        duration is, until stop_hand."""
        with self._lock:
            now = time.monotonic()
            return any(s.hand is not None and now < s.hand.end_time and not s.torque_on for s in self._servos.values())

    def wait_hand(self, timeout: float | None = None) -> bool:
        """Wait for the hand to end; False if `timeout` (s) passed first."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.hand_busy():
            if deadline is not None and time.monotonic() >= deadline:
                return False
            time.sleep(0.01)
        return True

    # -- faults

    def silence(self, servo_id: int) -> None:
        """The servo still receives and obeys, but never replies."""
        with self._lock:
            self._servo(servo_id).fault = "silent"

    def corrupt(self, servo_id: int) -> None:
        """The servo's replies carry a wrong checksum."""
        with self._lock:
            self._servo(servo_id).fault = "corrupt"

    def answer(self, servo_id: int) -> None:
        """The servo replies normally again (its own fault cleared; see answer_all for mute)."""
        with self._lock:
            self._servo(servo_id).fault = ""

    def mute_all(self) -> None:
        """No servo replies, all still receive and obey: a broken return line, or servo power
        lost, as the host sees it."""
        with self._lock:
            self._muted = True

    def answer_all(self) -> None:
        """Every fault cleared, mute included."""
        with self._lock:
            self._muted = False
            for servo in self._servos.values():
                servo.fault = ""

    def faults(self) -> dict[int, str]:
        """Each servo's reply state: "answers", "silent", "corrupt" or "muted"."""
        with self._lock:
            return {
                servo_id: "muted" if self._muted else (servo.fault or "answers")
                for servo_id, servo in self._servos.items()
            }

    def status_rows(self) -> list[dict[str, object]]:
        """One dict per servo, for a table: registers (signed decoded) and the joint."""
        rows = []
        with self._lock:
            now = time.monotonic()
            faults = self.faults()
            for servo_id, servo in self._servos.items():
                servo.advance(now, self.speed_steps_s)
                rows.append(
                    {
                        "id": servo_id,
                        "bus_id": servo.bus_id,
                        "joint": servo.mechanics.joint,
                        "torque": servo.torque_on,
                        "goal": sts3215.decode_signed(servo.get("Goal_Position"), 15),
                        "present": servo.get("Present_Position"),
                        "homing_offset": servo.homing_offset,
                        "limits": (servo.get("Min_Position_Limit"), servo.get("Max_Position_Limit")),
                        "physical": round(servo.physical) % sts3215.STEPS_PER_TURN,
                        "stops": (servo.mechanics.lower, servo.mechanics.upper),
                        "replies": faults[servo_id],
                    }
                )
        return rows

    # -- the bus

    def _serve(self) -> None:
        master, wake = self._master, self._wake_read
        buffer = self._buffer
        poller = select.poll()  # not select.select: it fails on descriptors past 1023
        poller.register(master, select.POLLIN)
        poller.register(wake, select.POLLIN)
        while True:
            timeout_ms = PARTIAL_PACKET_TIMEOUT_S * 1000 if buffer else None
            ready = {fd for fd, _ in poller.poll(timeout_ms)}
            if wake in ready:
                return
            if master in ready:
                try:
                    data = os.read(master, 4096)
                except BlockingIOError:
                    continue
                except OSError:
                    return
                if not data:
                    return
                buffer += data
            elif buffer:  # a partial packet that was never finished: drop it, look for the next header
                self._drop_head(buffer)
            reply = self._take_packets(buffer)
            if reply:
                try:
                    os.write(master, reply)
                except BlockingIOError:
                    pass  # nobody reads the port and its buffer is full: the bytes are lost, as on a bus
                except OSError:
                    return

    def _drop_head(self, buffer: bytearray) -> None:
        following = buffer.find(HEADER, 1)
        cut = following if following > 0 else len(buffer)
        with self._lock:
            self._counts["dropped_bytes"] += cut
        del buffer[:cut]

    def _take_packets(self, buffer: bytearray) -> bytes:
        """Handle every complete packet in `buffer` (removing it); the replies, in order."""
        replies = []
        while True:
            start = buffer.find(HEADER)
            if start < 0:
                keep = 1 if buffer[-1:] == b"\xff" else 0
                self._count_dropped(len(buffer) - keep)
                del buffer[: len(buffer) - keep]
                break
            if start:
                self._count_dropped(start)
                del buffer[:start]
            if len(buffer) < 4:
                break
            if buffer[2] == 0xFF:  # FF FF FF: the header is the later pair
                self._count_dropped(1)
                del buffer[0]
                continue
            length = buffer[3]
            if length < 2:
                self._count_dropped(2)
                del buffer[:2]
                continue
            total = length + 4
            if len(buffer) < total:
                break
            packet = bytes(buffer[:total])
            if checksum(packet[2:-1]) != packet[-1]:
                with self._lock:
                    self._counts["bad_checksums"] += 1
                del buffer[:2]  # resynchronise on the next FF FF
                continue
            del buffer[:total]
            replies.append(self._handle(packet[2], packet[4], packet[5:-1]))
        return b"".join(replies)

    def _count_dropped(self, count: int) -> None:
        if count:
            with self._lock:
                self._counts["dropped_bytes"] += count

    def _host_wrote(self, servo: _Servo, sent: dict[str, int]) -> None:
        # A calibration resets each servo's Homing_Offset to 0, torque off, in id order (so101 calibrate
        # first thing, LeRobot's lerobot-calibrate once the middle pose is taken, before the ranges):
        # that write to the first servo on the bus marks one. Driving an arm never writes Homing_Offset.
        if (sent.get("Homing_Offset") == 0 and not servo.torque_on and servo.mechanics.servo_id == min(self._servos)
                and self.on_calibration is not None):
            self.on_calibration()

    def _handle(self, target: int, instruction: int, params: bytes) -> bytes:
        with self._lock:
            self._counts["packets"] += 1
            now = time.monotonic()
            listening = [servo for servo in self._servos.values() if servo.hears_bus]
            broadcast = target == BROADCAST_ID
            servos = listening if broadcast else [s for s in listening if s.bus_id == target]
            if instruction == SYNC_READ:
                return self._sync_read(target, params, listening, now)
            if instruction == SYNC_WRITE:
                self._sync_write(target, params, listening, now)
                return b""
            if not servos:
                return b""
            for servo in servos:
                servo.advance(now, self.speed_steps_s)
            data = b""
            if instruction == PING:
                pass
            elif instruction == READ:
                if len(params) != 2 or params[0] + params[1] > MEMORY_SIZE:
                    return b""
                address, size = params
                data = bytes(servos[0].memory[address : address + size])
            elif instruction == WRITE:
                if len(params) < 2:
                    return b""
                for servo in servos:
                    self._host_wrote(servo, servo.host_write(params[0], params[1:]))
            elif instruction == REG_WRITE:
                if len(params) < 2:
                    return b""
                for servo in servos:
                    servo.pending = (params[0], bytes(params[1:]))
            elif instruction == ACTION:
                for servo in servos:
                    if servo.pending is not None:
                        self._host_wrote(servo, servo.host_write(*servo.pending))
                        servo.pending = None
            else:
                return b""  # an instruction the STS3215 does not know: no answer
            if broadcast:
                return b""
            return self._status(servos, target, data)

    def _status(self, servos: list[_Servo], reply_id: int, data: bytes) -> bytes:
        speaking = [] if self._muted else [servo for servo in servos if servo.fault != "silent"]
        if not speaking:
            return b""
        body = bytes([reply_id, len(data) + 2, 0]) + data
        check = checksum(body)
        if len(speaking) > 1 or speaking[0].fault == "corrupt":
            check ^= 0xFF  # two servos talking at once garble each other
        self._counts["replies"] += 1
        return HEADER + body + bytes([check])

    def _sync_read(self, target: int, params: bytes, listening: list[_Servo], now: float) -> bytes:
        if target != BROADCAST_ID or len(params) < 3:
            return b""
        address, size = params[0], params[1]
        if address + size > MEMORY_SIZE:
            return b""
        replies = []
        for servo_id in params[2:]:
            servos = [servo for servo in listening if servo.bus_id == servo_id]
            if not servos:
                continue
            for servo in servos:
                servo.advance(now, self.speed_steps_s)
            replies.append(self._status(servos, servo_id, bytes(servos[0].memory[address : address + size])))
        return b"".join(replies)

    def _sync_write(self, target: int, params: bytes, listening: list[_Servo], now: float) -> None:
        if target != BROADCAST_ID or len(params) < 3:
            return
        address, size = params[0], params[1]
        chunks = params[2:]
        if size == 0 or len(chunks) % (size + 1):
            return  # malformed: the servos cannot tell where each one's data starts
        for start in range(0, len(chunks), size + 1):
            servo_id, data = chunks[start], chunks[start + 1 : start + 1 + size]
            for servo in listening:
                if servo.bus_id == servo_id:
                    servo.advance(now, self.speed_steps_s)
                    self._host_wrote(servo, servo.host_write(address, data))


# -- a calibrated arm ---------------------------------------------------------------------------

def calibrate_as_at_the_factory(arm: FakeArm):
    """Write into `arm`'s servos the calibration a person's `so101 calibrate` would find (the
    middle pose at each joint's centre, the ranges at its stops, wrist_roll the whole turn) and
    return it, in so101.feetech.calibration's form: an emulated arm ready for the driver, for tests and
    `so101 bench --body real`."""
    from so101.feetech.calibration import MOTOR_NAMES, MotorCalibration, homing_offset

    calibration = {}
    for servo_id in arm.ids:
        mechanics = arm.mechanics(servo_id)
        offset = homing_offset(mechanics.centre)
        stops = mechanics.stops
        low, high = (stops[0] - offset, stops[1] - offset) if stops is not None else (0, sts3215.MAX_STEP)
        for name, value in (("Homing_Offset", offset), ("Min_Position_Limit", low), ("Max_Position_Limit", high)):
            arm.write_register(servo_id, name, value)
        arm.write_register(servo_id, "Goal_Position", arm.read_register(servo_id, "Present_Position"))
        calibration[MOTOR_NAMES[servo_id - 1]] = MotorCalibration(servo_id, 0, offset, low, high)
    return calibration
