"""An emulated SO-101 servo bus on a pseudo-terminal (`so101 fake-arm`, so101/cli/fake_arm.py).

Six Feetech STS3215 servos (IDs 1-6) answer Feetech's serial protocol (protocol.py) on a
pseudo-terminal such as /dev/pts/7, so the real-arm driver, `so101 calibrate` and their tests run
without hardware. It emulates the protocol, the register table (servo.py, so101/feetech/sts3215.py)
and an assembled arm's hard stops (mechanics.py); it is not a physics model: no gravity, no load, no
inertia, a constant speed (or, given a servo.Response, goals taken late and a gap closed with a time
constant, for a fit to find). Motion is computed lazily from the clock whenever a register is read or
written. Torque off, a hand can move the joints (hand_paths.py: `move_by_hand`, `sweep`, and
`play_hand`, which plays a script of angles such as so101/feetech/hand.py's figure eight: the
emulator then plays a leader arm). Faults are injected through faults.py.

As on a real bus: broadcast instructions (other than SYNC_READ) get no answer, an ID that is not
on the bus gets no answer, a write to ID moves the servo to its new ID (it answers that write
from the old one), and two servos that answer at once collide: the host gets one packet with a
wrong checksum. `values_written` lists what the bus wrote to a register.

A host that resets the first servo's Homing_Offset to 0 with torque off is starting a calibration:
`calibrations_begun` counts them and `on_calibration` is called (`so101 fake-arm` tells the person
to type `sweep`).

Tests run it in a process of its own (process.py), so that nothing a test does starves it.
"""

from __future__ import annotations

import os
import select
import threading
import time
import tty
from typing import Callable, Sequence

from so101.feetech import sts3215
from so101.feetech.fake_arm.faults import ANSWERS, CORRUPT, SILENT, Faults
from so101.feetech.fake_arm.hand_paths import ScriptedHand, sweep_path
from so101.feetech.fake_arm.mechanics import ALL_IDS, MECHANICS, Mechanics, joint_deg
from so101.feetech.fake_arm.protocol import (
    ACTION, BROADCAST_ID, PARTIAL_PACKET_TIMEOUT_S, PING, READ, REG_WRITE, SYNC_READ, SYNC_WRITE, WRITE,
    Instruction, PacketReader,
)
from so101.feetech.fake_arm.servo import (
    DEFAULT_SPEED_STEPS_S, FIRST_READ_ONLY, FIRST_WRITABLE, MEMORY_SIZE, Response, Servo,
)
from so101.feetech.hand import eased_in
from so101.robot import ACTUATED_JOINTS, goal_deg


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
        clock: Callable[[], float] = time.monotonic,
        response: Response = Response(),
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
        # Every motion (motors, hands) is computed from this clock: a test may make it run faster than
        # the wall clock (process.scaled_clock).
        self.clock = clock
        self._lock = threading.RLock()
        now = self.clock()
        self._servos = {
            servo_id: Servo(MECHANICS[servo_id], start_positions.get(servo_id, MECHANICS[servo_id].centre), now, response)
            for servo_id in ids
        }
        self._faults = Faults(ids)
        self._packets = self._replies = 0
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.port = os.ttyname(self._slave)
        self._wake_read, self._wake_write = os.pipe()
        self._thread: threading.Thread | None = None
        self._port_open = True
        self._reader = PacketReader()
        # Called (from the bus thread, so briefly) when a host starts a calibration; see _host_wrote.
        self.on_calibration: Callable[[], None] | None = None
        self.calibrations_begun = 0

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
        return self._packets

    def stats(self) -> dict[str, int]:
        """Counters: packets (good ones received), replies (status packets sent),
        bad_checksums (packets ignored), dropped_bytes (noise and stale partial packets)."""
        with self._lock:
            return {"packets": self._packets, "replies": self._replies,
                    "bad_checksums": self._reader.bad_checksums, "dropped_bytes": self._reader.dropped_bytes}

    # -- registers and the joint, for tests and tools

    def _servo(self, servo_id: int) -> Servo:
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
            servo.advance(self.clock(), self.speed_steps_s)
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
            servo.advance(self.clock(), self.speed_steps_s)
            servo.write(address, raw.to_bytes(size, "little"))

    def values_written(self, servo_id: int, name: str) -> frozenset[int]:
        """Every value the bus (WRITE, REG_WRITE then ACTION, SYNC_WRITE) ever wrote to this register of
        servo `servo_id`, as sent, whether or not the servo kept it (signed registers decoded); a write
        counts for each register it covers whole. Not write_register's: those are the test's own."""
        if name not in sts3215.REGISTERS:
            raise KeyError(f"no register {name!r}; see so101/feetech/sts3215.py")
        with self._lock:
            return frozenset(self._servo(servo_id).written[name])

    def goals_written(self, servo_id: int) -> tuple[int, ...]:
        """Every Goal_Position the bus wrote to servo `servo_id`, in order (the last servo.GOALS_KEPT), as sent."""
        with self._lock:
            return tuple(self._servo(servo_id).goals)

    def physical_position(self, servo_id: int) -> int:
        """The joint's encoder reading before the homing offset (steps, 0..4095)."""
        with self._lock:
            servo = self._servo(servo_id)
            servo.advance(self.clock(), self.speed_steps_s)
            return round(servo.physical) % sts3215.STEPS_PER_TURN

    def joint_angle_deg(self, servo_id: int) -> float:
        """The joint's angle in degrees as the arm calibrated at the factory reads it (joint_deg)."""
        with self._lock:
            servo = self._servo(servo_id)
            servo.advance(self.clock(), self.speed_steps_s)
            return joint_deg(servo.mechanics, servo.physical)

    def mechanics(self, servo_id: int) -> Mechanics:
        """The joint's middle and hard stops (physical steps)."""
        return self._servo(servo_id).mechanics

    def power_cycle(self) -> None:
        """Power off and on: EEPROM back to what was saved (written with Lock = 0), RAM to its
        power-up values (torque off, Goal_Position = present, Lock = 1). The joints stay put."""
        with self._lock:
            now = self.clock()
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
            servo.advance(self.clock(), self.speed_steps_s)
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
            now = self.clock()
            for servo_id in ids if ids is not None else self.ids:
                servo = self._servo(servo_id)
                servo.advance(now, self.speed_steps_s)
                if servo.torque_on:
                    continue
                swept.append(servo_id)
                servo.hand = sweep_path(servo.mechanics, servo.physical, now, duration_s)
        return tuple(swept)

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
            now = self.clock()
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
                servo.hand = ScriptedHand(script, servo.mechanics, now, duration_s)
        return tuple(moved)

    def stop_hand(self) -> tuple[int, ...]:
        """The hand lets go (a sweep or a script): every joint stays where it is. Returns the ids it
        was still moving."""
        let_go = []
        with self._lock:
            now = self.clock()
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
            now = self.clock()
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
            self._faults.set(self._servo(servo_id).mechanics.servo_id, SILENT)

    def corrupt(self, servo_id: int) -> None:
        """The servo's replies carry a wrong checksum."""
        with self._lock:
            self._faults.set(self._servo(servo_id).mechanics.servo_id, CORRUPT)

    def answer(self, servo_id: int) -> None:
        """The servo replies normally again (its own fault cleared; see answer_all for mute)."""
        with self._lock:
            self._faults.set(self._servo(servo_id).mechanics.servo_id, ANSWERS)

    def mute_all(self) -> None:
        """No servo replies, all still receive and obey: a broken return line, or servo power
        lost, as the host sees it."""
        with self._lock:
            self._faults.muted = True

    def answer_all(self) -> None:
        """Every fault cleared, mute included."""
        with self._lock:
            self._faults.clear()

    def faults(self) -> dict[int, str]:
        """Each servo's reply state: "answers", "silent", "corrupt" or "muted"."""
        with self._lock:
            return self._faults.states()

    def status_rows(self) -> list[dict[str, object]]:
        """One dict per servo, for a table: registers (signed decoded) and the joint."""
        rows = []
        with self._lock:
            now = self.clock()
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
        reader = self._reader
        poller = select.poll()  # not select.select: it fails on descriptors past 1023
        poller.register(master, select.POLLIN)
        poller.register(wake, select.POLLIN)
        while True:
            timeout_ms = PARTIAL_PACKET_TIMEOUT_S * 1000 if reader.waiting else None
            ready = {fd for fd, _ in poller.poll(timeout_ms)}
            if wake in ready:
                return
            data = b""
            if master in ready:
                try:
                    data = os.read(master, 4096)
                except BlockingIOError:
                    continue
                except OSError:
                    return
                if not data:
                    return
            elif reader.waiting:
                reader.drop_partial()
            with self._lock:
                reply = b"".join(self._handle(packet) for packet in reader.feed(data))
            if reply:
                try:
                    os.write(master, reply)
                except BlockingIOError:
                    pass  # nobody reads the port and its buffer is full: the bytes are lost, as on a bus
                except OSError:
                    return

    def _host_wrote(self, servo: Servo, sent: dict[str, int]) -> None:
        # A calibration resets each servo's Homing_Offset to 0, torque off, in id order (so101 calibrate
        # first thing, LeRobot's lerobot-calibrate once the middle pose is taken, before the ranges):
        # that write to the first servo on the bus marks one. Driving an arm never writes Homing_Offset.
        if sent.get("Homing_Offset") == 0 and not servo.torque_on and servo.mechanics.servo_id == min(self._servos):
            self.calibrations_begun += 1
            if self.on_calibration is not None:
                self.on_calibration()

    def _handle(self, packet: Instruction) -> bytes:
        target, instruction, params = packet.target, packet.instruction, packet.params
        with self._lock:
            self._packets += 1
            now = self.clock()
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

    def _status(self, servos: list[Servo], reply_id: int, data: bytes) -> bytes:
        reply = self._faults.reply(servos, reply_id, data)
        self._replies += bool(reply)
        return reply

    def _sync_read(self, target: int, params: bytes, listening: list[Servo], now: float) -> bytes:
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

    def _sync_write(self, target: int, params: bytes, listening: list[Servo], now: float) -> None:
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
