"""The real SO-101 follower arm as a body (so101.bodies.protocol.Body): six STS3215 servos on a Feetech bus.

`SO101Real` takes goals in the URDF's degrees and, once per tick (`step`), writes the
next Goal_Position of each servo with one SYNC WRITE and reads every Present_Position
with one SYNC READ. The safety rules live here, so every user of the body has them:
- it starts only with a calibration that matches the servos on the bus;
- torque goes on with each goal equal to where the joint stands (no jump);
- goals are clamped to the URDF's limits and to the calibrated range;
- the goal sent moves by at most `max_speed_deg_s` x the tick per tick (a ramp, not a slam);
- `close()` switches torque off (the node calls it on STOP, Ctrl-C, SIGTERM, an exception
  and a lost bus);
- a servo that stops answering is retried for `retries` ticks, publishing no angle meanwhile,
  then the body fails with one line naming the servo.
"""

from __future__ import annotations

import logging
import time
from array import array
from typing import NoReturn, Sequence

from so101.bodies.node_loop import TAGS
from so101.bodies.protocol import BodyFailed, BodyName
from so101.bodies.settings import CALIBRATE_HINT, DEFAULT_BUS_RETRIES, DEFAULT_MAX_SPEED_DEG_S, ArmSettings, NodeSettings
from so101.feetech.bus import BusError, BusLost, FeetechBus, ServoSilent
from so101.feetech.calibration import (
    MOTOR_IDS,
    MOTOR_NAMES,
    Calibration,
    CalibrationError,
    goal_steps,
    load_calibration,
    step_toward,
    steps_to_deg,
)
from so101.feetech.checks import at_start, check_calibration_on_servos, check_servos_answer
from so101.robot import ACTUATED_JOINTS, goal_deg
from so101.stats import percentile

logger = logging.getLogger(__name__)

# Round trips measured before the first tick, for the log's "bus round trip" figure.
PROBE_READS = 20
# Reads of Torque_Enable after torque off before a servo that says "on" is believed, and the gap between.
TORQUE_OFF_READS = 3
TORQUE_OFF_READ_GAP_S = 0.02

# The log's lines, in the node's language; {tag} is the arm node's (so101.bodies.node_loop.TAGS).
TEXT = {
    "zh": {
        "retrying": "{tag} {error};重试,最多 {retries} 次",
        "again": "{tag} {count} 次读取失败后,舵机恢复应答",
        "still_on": "{tag} 有舵机仍报告扭矩开着:请关掉机械臂的电源",
        "torque_off": "{tag} 舵机 1-6 扭矩已关闭;本次运行的总线往返:{summary}",
        "unconfirmed": "{tag} 无法确认扭矩已关闭({error}):请关掉机械臂的电源",
        "no_reads": "没有读数",
    },
    "en": {
        "retrying": "{tag} {error}; retrying, up to {retries} times",
        "again": "{tag} the servos answer again after {count} failed read(s)",
        "still_on": "{tag} a servo still reports torque on: switch the arm's power off",
        "torque_off": "{tag} torque off on servos 1-6; bus round trip over the run: {summary}",
        "unconfirmed": "{tag} could not confirm torque off ({error}): switch the arm's power off",
        "no_reads": "no reads",
    },
}


class ArmFailed(BodyFailed):
    """The arm cannot start or go on; the message is one line for the user."""


def check_node_settings(settings: NodeSettings) -> None:
    """Refuses, in one line, what the shared loop offers the simulations but the arm must not take:
    pictures (it has no camera) and fast mode (its goals ramp by the tick: ticks made up as fast as
    the bus answers would move it faster than SO101_MAX_SPEED_DEG_S)."""
    if settings.image_hz > 0:
        raise ValueError("the real arm has no camera: set SO101_IMAGE_HZ to 0")
    if settings.fast_steps > 0:
        raise ValueError("the real arm has no fast mode (its goals ramp by the tick): set SO101_FAST_STEPS to 0")
    if settings.task:
        raise ValueError(f"the real arm has no task scene (nothing reports where real objects are, so no object_state): "
                         f"SO101_TASK={settings.task} is for a simulation; leave it empty")


def _percentiles_ms(samples_s: Sequence[float], no_reads: str) -> str:
    if not samples_s:
        return no_reads
    return (f"p50 {percentile(samples_s, 0.50) * 1000:.2f} ms, p99 {percentile(samples_s, 0.99) * 1000:.2f} ms, "
            f"max {max(samples_s) * 1000:.2f} ms")


class SO101Real:
    """The arm on `port`, with `calibration` (LeRobot's format), logging in `lang`. Raises ArmFailed if it must not start."""

    kind: BodyName = "real"
    display_mode: None = None  # hardware: no window, no headless rendering
    scene: None = None  # no task: nothing reports where real objects are

    def __init__(self, port: str, calibration: Calibration, *, calibration_name: str = "the calibration",
                 joint_signs: tuple[int, ...] = (1,) * 6, max_speed_deg_s: float = DEFAULT_MAX_SPEED_DEG_S,
                 torque_limit_percent: float = 100.0, retries: int = DEFAULT_BUS_RETRIES,
                 time_step_s: float = 0.02, lang: str = "en"):
        self.port = port
        self.text = {key: line.replace("{tag}", TAGS["arm"][lang]) for key, line in TEXT[lang].items()}
        self._motors = [calibration[name] for name in MOTOR_NAMES]
        self._signs = joint_signs
        self.max_speed_deg_s = max_speed_deg_s
        self.retries = retries
        self.steps = 0
        self.round_trips_s: array[float] = array("d")
        self._failed_reads = 0
        self.set_time_step_s(time_step_s)
        # None once closed.
        self.bus: FeetechBus | None = None
        try:
            bus = self.bus = FeetechBus(port).open()
            self._check_servos(bus, calibration_name)
            present = at_start(lambda: self._read_present(bus))
            start_deg = self._to_deg(present)
            self._check_in_range(present, start_deg)
            # Torque on with each goal where the joint stands: the arm holds still.
            bus.sync_write("Goal_Position", present)
            bus.sync_write("Torque_Limit", {i: round(torque_limit_percent * 10) for i in MOTOR_IDS})
            bus.sync_write("Torque_Enable", {i: 1 for i in MOTOR_IDS})
            for _ in range(PROBE_READS):
                try:
                    self._read_present(bus)
                except (ServoSilent, BusLost):  # a lost or cut-short reply is a missing sample, not an arm that
                    continue                        # cannot start (a port really gone fails the first tick's read)
        except BusError as error:
            self.close()
            raise ArmFailed(str(error)) from None
        except BaseException:
            self.close()
            raise
        # The angles read this tick; None when this tick's read failed.
        self._angles_deg: tuple[float, ...] | None = start_deg
        self._sent_deg = self._targets_deg = self._start_deg = start_deg

    @classmethod
    def from_settings(cls, settings: ArmSettings, lang: str = "en") -> "SO101Real":
        return cls(
            settings.port, load_calibration(settings.calibration_file), calibration_name=str(settings.calibration_file),
            joint_signs=settings.joint_signs, max_speed_deg_s=settings.max_speed_deg_s,
            torque_limit_percent=settings.torque_limit_percent, retries=settings.retries, lang=lang,
        )

    # -- start-up checks ------------------------------------------------------------------

    def _check_servos(self, bus: FeetechBus, calibration_name: str) -> None:
        check_servos_answer(bus)
        try:
            check_calibration_on_servos(bus, self._motors, calibration_name, "arm",
                                        CALIBRATE_HINT.format(port=self.port) + " for this arm")
        except CalibrationError as error:
            raise ArmFailed(str(error)) from None

    def _check_in_range(self, present: dict[int, int], angles_deg: tuple[float, ...]) -> None:
        # The servo clamps goals to its limits: torque on outside them would jump to the limit.
        for name, servo_id, motor, angle in zip(MOTOR_NAMES, MOTOR_IDS, self._motors, angles_deg):
            if not motor.range_min <= present[servo_id] <= motor.range_max:
                raise ArmFailed(f"{name} stands at {angle:.1f}°, outside its calibrated range: "
                                "move it inside by hand (torque is off) and start again")

    # -- the body's surface (so101.bodies.protocol.Body) ---------------------------------

    def _read_present(self, bus: FeetechBus) -> dict[int, int]:
        present = bus.sync_read("Present_Position", MOTOR_IDS)
        self.round_trips_s.append(bus.last_round_trip_s)
        return present

    def _to_deg(self, present: dict[int, int]) -> tuple[float, ...]:
        return tuple(
            steps_to_deg(index, present[servo_id], motor, sign)
            for index, (servo_id, motor, sign) in enumerate(zip(MOTOR_IDS, self._motors, self._signs))
        )

    def start_targets_deg(self) -> tuple[float, ...]:
        """Where the arm stood at start: a one-joint command leaves the other joints there."""
        return self._start_deg

    def set_time_step_s(self, time_step_s: float) -> None:
        self.time_step_s = time_step_s
        self.max_step_deg = self.max_speed_deg_s * time_step_s

    def set_targets_deg(self, targets_deg: Sequence[float]) -> None:
        """New goals, clamped to the URDF's limits; `step` ramps toward them."""
        goal = goal_deg(targets_deg)
        self._targets_deg = tuple(joint.clamp_deg(angle) for angle, joint in zip(goal, ACTUATED_JOINTS))

    def step(self, count: int = 1) -> None:
        """One bus exchange, whatever `count` (a late tick does not make the arm hurry):
        the ramped goals out, the present positions in."""
        if self.bus is None:
            raise ArmFailed(f"the arm on {self.port} is closed")
        try:
            self._exchange(self.bus)
        except BusError as error:
            raise ArmFailed(str(error)) from None
        self.steps += 1

    def _exchange(self, bus: FeetechBus) -> None:
        self._sent_deg = step_toward(self._sent_deg, self._targets_deg, self.max_step_deg)
        bus.sync_write("Goal_Position", {
            servo_id: goal_steps(index, angle, motor, sign)
            for index, (servo_id, motor, sign, angle) in enumerate(zip(MOTOR_IDS, self._motors, self._signs, self._sent_deg))
        })
        try:
            present = self._read_present(bus)
        except BusError as error:
            self._angles_deg = None  # nothing fresh to publish this tick
            self._failed_reads += 1
            if self._failed_reads > self.retries:
                raise BusError(f"{error}; still failing after {self.retries} retries, torque off") from None
            if self._failed_reads == 1:
                logger.warning(self.text["retrying"].format(error=error, retries=self.retries))
            return
        if self._failed_reads:
            logger.info(self.text["again"].format(count=self._failed_reads))
            self._failed_reads = 0
        self._angles_deg = self._to_deg(present)

    def joint_angles_deg(self) -> tuple[float, ...] | None:
        """The six angles read this tick, or None when this tick's read failed (never stale ones)."""
        return self._angles_deg

    @property
    def sim_time_s(self) -> float:
        return self.steps * self.time_step_s

    def reset_task(self, seed: int) -> NoReturn:
        raise ValueError("the real arm has no task scene to lay out")

    def render_rgb(self, width: int, height: int, camera: object = None) -> NoReturn:
        raise ValueError("the real arm has no camera: set SO101_IMAGE_HZ to 0")

    def round_trip_summary(self) -> str:
        return _percentiles_ms(self.round_trips_s, self.text["no_reads"])

    def close(self) -> None:
        """Torque off on every servo, then the port closed; safe twice."""
        bus, self.bus = self.bus, None
        if bus is None:
            return
        try:
            bus.sync_write("Torque_Enable", {i: 0 for i in MOTOR_IDS})
            if not self._torque_confirmed_off(bus):
                logger.error(self.text["still_on"])
            else:
                logger.info(self.text["torque_off"].format(summary=self.round_trip_summary()))
        except BusError as error:
            logger.error(self.text["unconfirmed"].format(error=error))
        finally:
            bus.close()

    @staticmethod
    def _torque_confirmed_off(bus: FeetechBus) -> bool:
        # Ctrl-C can cut an exchange short with its replies still on the way; one of them, read as
        # this answer, would say "on". So an "on" is read again before it is believed.
        for _ in range(TORQUE_OFF_READS):
            if not any(bus.sync_read("Torque_Enable", MOTOR_IDS).values()):
                return True
            time.sleep(TORQUE_OFF_READ_GAP_S)
        return False

    def __enter__(self) -> "SO101Real":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

