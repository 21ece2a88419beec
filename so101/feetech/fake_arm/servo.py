"""One emulated STS3215: its register memory and the motion of its joint.

Positions, as the STS3215 does them (all in encoder steps, 4096 per turn):
    Present_Position = (physical - Homing_Offset) mod 4096     (Homing_Offset: sign bit 11)
    Goal_Position g  -> the servo drives its Present_Position to g, clamped to
                        [Min_Position_Limit, Max_Position_Limit] unless both are 0
With Torque_Enable = 1 the motor moves toward the goal at a constant speed (Goal_Velocity if
not 0, capped at the motor's speed) without crossing the 0/4095 seam of its own (offset)
frame, as a servo in position mode does; the hard stops stop it. `advance(now)` brings the
joint to `now`, so the motion is exact however often, or seldom, the bus is polled. With
Torque_Enable = 0 the motor does not move by itself, but a hand can move it (hand_paths.py).
Writing 128 to Torque_Enable sets Homing_Offset so that the current position reads 2048
(Feetech's "middle position calibration"). Only position mode (Operating_Mode 0) is
emulated; Goal_Time and Acceleration are stored but not emulated (the speed is constant, a
new goal takes effect at once).

EEPROM (addresses below 40) behaves as Feetech describes the Lock register: a write takes
effect at once; it is kept through a power cycle only if it was made with Lock = 0. A servo
whose Baud_Rate register is set to anything but 0 (1,000,000 baud) no longer hears the bus,
as a real one listening at another speed.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from so101.feetech import sts3215
from so101.feetech.fake_arm.hand_paths import HandPath, ScriptedHand
from so101.feetech.fake_arm.mechanics import MIDDLE, Mechanics

MEMORY_SIZE = 256  # the register memory, addresses 0-255; a READ past its end gets no answer
_ADDRESS = {name: address for name, (address, _) in sts3215.REGISTERS.items()}
# Addresses 0-4 (firmware version, Model_Number) and everything from Present_Position on are
# the servo's to write; a host's write to them is ignored, as by a real servo.
FIRST_WRITABLE = _ADDRESS["ID"]
FIRST_READ_ONLY = _ADDRESS["Present_Position"]
CALIBRATE_MIDDLE = 128  # written to Torque_Enable: the current position becomes 2048
BAUD_INDEX_1M = 0  # Baud_Rate register value for 1,000,000 baud: the bus this emulates

# The motor's top speed with Goal_Velocity = 0, in steps/s: 3000 steps/s ≈ 264°/s, near an
# STS3215's no-load speed at 7.4 V (0.222 s per 60°, ≈ 270°/s). Load would slow a real one.
DEFAULT_SPEED_STEPS_S = 3000.0
SUPPLY_DECIVOLTS = 120  # Present_Voltage: 12.0 V
TEMPERATURE_C = 30  # Present_Temperature
GOALS_KEPT = 100_000  # Goal_Position writes kept per servo: over half an hour of a driver at 50 Hz

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


@dataclass(frozen=True)
class Response:
    """How a servo answers a new goal beyond what its registers say, so that a fit has a known answer
    (`so101 physics --fit`). A real follower acts on a goal late: its bus, its loop and the host add up
    to about 130 ms on a public LeRobot recording. Its P loop closes the last of a gap gradually, with
    a time constant; at 0 (the default) the motor runs at its top speed right onto the goal."""

    delay_s: float = 0.0
    time_constant_s: float = 0.0

    def __post_init__(self) -> None:
        for name in ("delay_s", "time_constant_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and 0 <= value <= 2):
                raise ValueError(f"a servo's {name} is a number of seconds from 0 to 2, got {value!r}")


def closing(gap: float, speed: float, time_constant_s: float, elapsed: float) -> tuple[float, float]:
    """How far a motor `gap` steps from its goal travels in `elapsed` seconds, and its speed then: at most
    `speed` steps/s, and no faster than the gap over `time_constant_s` (a P loop's exponential approach)."""
    at_top_speed_s = max(0.0, (gap - speed * time_constant_s) / speed)
    if elapsed <= at_top_speed_s:
        return speed * elapsed, speed
    left = min(gap, speed * time_constant_s) * math.exp(-(elapsed - at_top_speed_s) / time_constant_s)
    return gap - left, left / time_constant_s


class Servo:
    """One STS3215: its register memory and the physical position of its joint."""

    def __init__(self, mechanics: Mechanics, physical: float, now: float, response: Response = Response()):
        self.mechanics = mechanics
        self.response = response
        # With a delay: the Goal_Position the motor acts on (raw), and the later writes, each with the
        # time it takes effect. Without one the motor acts on the register as it is.
        self.acting_goal_raw = 0
        self.goal_changes: deque[tuple[float, int]] = deque()
        self.memory = bytearray(MEMORY_SIZE)
        self.physical = float(physical)  # encoder steps, inside the stops (or 0..4096 without)
        self.velocity = 0.0  # steps/s at self.time
        self.time = now
        self.hand: HandPath | ScriptedHand | None = None
        # Every value the bus wrote, by register (FakeArm.values_written).
        self.written: dict[str, set[int]] = {name: set() for name in sts3215.REGISTERS}
        # Every Goal_Position the bus wrote, in order (FakeArm.goals_written): a driver's ramp is checked
        # write by write. Bounded: an emulator left running for hours keeps its last GOALS_KEPT.
        self.goals: deque[int] = deque(maxlen=GOALS_KEPT)
        self.pending: tuple[int, bytes] | None = None  # REG_WRITE, until ACTION
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
        self.acting_goal_raw = self.get("Goal_Position")
        self.goal_changes.clear()

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
        raw = self.acting_goal_raw if self.response.delay_s else self.get("Goal_Position")
        goal = sts3215.decode_signed(raw, 15)
        low, high = self.get("Min_Position_Limit"), self.get("Max_Position_Limit")
        if low == 0 and high == 0:
            # No limits: the STS3215's multi-turn use. Approximated: goals past 0..4095 add turns.
            return goal
        return min(max(goal, low), high)

    def speed(self, top_speed: float) -> float:
        asked = abs(sts3215.decode_signed(self.get("Goal_Velocity"), sts3215.SIGN_BITS["Goal_Velocity"]))
        return min(float(asked), top_speed) if asked else top_speed

    def advance(self, now: float, top_speed: float) -> None:
        """Bring the joint to `now`: the hand's path, or the motor toward its goal (each delayed goal
        taken at its own time)."""
        start = self.time
        self.time = max(self.time, now)
        if self.hand is not None and not self.torque_on:
            position, self.velocity = self.hand.at(now)
            self.physical = self.mechanics.clamp(position)
            if now >= self.hand.end_time:
                self.hand = None
        elif self.torque_on:
            self.hand = None
            while self.goal_changes and self.goal_changes[0][0] <= now:
                at, goal_raw = self.goal_changes.popleft()
                self._drive(max(0.0, at - start), top_speed)  # toward the goal before, until this one takes effect
                start, self.acting_goal_raw = max(start, at), goal_raw
            self._drive(max(0.0, now - start), top_speed)
        else:
            self.velocity = 0.0
        self.refresh()

    def _drive(self, elapsed: float, top_speed: float) -> None:
        """The motor, `elapsed` seconds toward the goal it acts on."""
        present = (self.physical - self.homing_offset) % sts3215.STEPS_PER_TURN
        error = self.goal() - present
        speed = self.speed(top_speed)
        direction = 1.0 if error > 0 else -1.0
        if self.response.time_constant_s:
            travel, speed = closing(abs(error), speed, self.response.time_constant_s, elapsed)
            arrived = abs(error) - travel < 0.5  # within half a step: the encoder reads the goal
        else:
            travel = min(abs(error), speed * elapsed)
            arrived = travel >= abs(error)
        wanted = self.physical + (error if arrived else direction * travel)
        self.physical = self.mechanics.clamp(wanted)
        blocked = self.mechanics.has_stops and self.physical != wanted
        self.velocity = 0.0 if arrived or blocked else direction * speed

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
        was_on = self.torque_on
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
        self._take_goal(late=was_on and self.torque_on)
        self.refresh()

    def _take_goal(self, late: bool) -> None:
        """The register's goal for the motor: `response.delay_s` from now while the motor runs, at once
        when it starts or is off (a driver sets the goal to where the joint is before it starts it)."""
        goal_raw = self.get("Goal_Position")
        if not late or not self.response.delay_s:
            self.acting_goal_raw = goal_raw
            self.goal_changes.clear()
        elif goal_raw != (self.goal_changes[-1][1] if self.goal_changes else self.acting_goal_raw):
            self.goal_changes.append((self.time + self.response.delay_s, goal_raw))

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
        if "Goal_Position" in sent:
            self.goals.append(sent["Goal_Position"])
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
