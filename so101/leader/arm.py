"""The SO-101 leader arm on its bus: six STS3215 servos with torque off, read once a tick.

`SO101Leader` starts only with a calibration that matches the servos (as the follower does),
switches off any torque it finds on (a leader is moved by hand; this is the one register it
writes, and only ever to 0), and reads every Present_Position with one SYNC READ a tick
(`poll`). A leader that stops answering or is unplugged is never fatal: the node sends nothing,
so the body holds where it is, and the log says so once.
"""

from __future__ import annotations

import logging

from so101.feetech.bus import BusError, BusLost, FeetechBus
from so101.feetech.calibration import MOTOR_IDS, MOTOR_NAMES, Calibration, CalibrationError, load_calibration
from so101.feetech.checks import check_calibration_on_servos, check_servos_answer
from so101.leader.command import leader_command_deg
from so101.leader.settings import CALIBRATE_LEADER_HINT, LeaderSettings

logger = logging.getLogger(__name__)

TEXT = {
    "zh": {
        "torque_was_on": "[主臂] 舵机 {ids} 的扭矩是开着的,已关闭:主臂靠手移动",
        "silent": "[主臂] {error};已连续 {count} 次读取失败,从动端保持原位,每个 tick 重试",
        "lost": "[主臂] {error};从动端保持原位,插回后请重新启动",
        "again": "[主臂] 主臂恢复应答({count} 次读取失败之后)",
    },
    "en": {
        "torque_was_on": "[leader] torque was on at servo(s) {ids}: switched off (a leader is moved by hand)",
        "silent": "[leader] {error}; {count} reads failed in a row: the body holds where it is, retrying every tick",
        "lost": "[leader] {error}; the body holds where it is: plug it back and start again",
        "again": "[leader] the leader answers again after {count} failed read(s)",
    },
}


class LeaderFailed(Exception):
    """The leader cannot start; the message is one line for the user."""


class SO101Leader:
    """The leader on `port` with `calibration` (LeRobot's so101_leader format). Raises LeaderFailed if it must not start.
    `report(line)` receives the lines a person should see (torque found on, a silence, the leader back)."""

    def __init__(self, port: str, calibration: Calibration, *, calibration_name: str = "the calibration",
                 retries: int = 5, lang: str = "en", report=logger.warning):
        self.port = port
        self._motors = [calibration[name] for name in MOTOR_NAMES]
        self.retries = retries
        self.text = TEXT[lang]
        self.report = report
        self.failed_reads = 0
        self.lost = False
        self.latest_deg: tuple[float, ...] | None = None  # the last reading, for the takeover rule
        self.bus: FeetechBus | None = None
        try:
            bus = self.bus = FeetechBus(port).open()
            check_servos_answer(bus)
            check_calibration_on_servos(bus, self._motors, calibration_name, "leader",
                                        CALIBRATE_LEADER_HINT.format(port=port) + " for this leader")
            self.torque_found_on = self._switch_torque_off(bus)
            self.latest_deg = leader_command_deg(bus.sync_read("Present_Position", MOTOR_IDS), self._motors)
        except (BusError, CalibrationError) as error:
            self.close()
            raise LeaderFailed(str(error)) from None
        except BaseException:
            self.close()
            raise

    @classmethod
    def from_settings(cls, settings: LeaderSettings, report=logger.warning) -> "SO101Leader":
        try:
            calibration = load_calibration(settings.calibration_file, role="leader")
        except CalibrationError as error:
            raise LeaderFailed(str(error)) from None
        return cls(settings.port, calibration, calibration_name=str(settings.calibration_file),
                   retries=settings.retries, lang=settings.lang, report=report)

    def _switch_torque_off(self, bus: FeetechBus) -> tuple[int, ...]:
        """Torque off wherever it is on; the IDs that had it on."""
        torque = bus.sync_read("Torque_Enable", MOTOR_IDS)
        found_on = tuple(servo_id for servo_id, value in torque.items() if value)
        if found_on:
            bus.sync_write("Torque_Enable", {servo_id: 0 for servo_id in found_on})
            self.report(self.text["torque_was_on"].format(ids=", ".join(map(str, found_on))))
        return found_on

    def poll(self) -> tuple[float, ...] | None:
        """This tick's reading as the follower's six targets (degrees); None when the leader did not
        answer (never the last reading again)."""
        if self.bus is None:
            return None
        try:
            present = self.bus.sync_read("Present_Position", MOTOR_IDS)
        except BusLost as error:
            self.lost = True
            self.report(self.text["lost"].format(error=error))
            self.close()
            return None
        except BusError as error:
            self.failed_reads += 1
            if self.failed_reads == self.retries + 1:  # a glitch or two passes quietly; a silence is said once
                self.report(self.text["silent"].format(error=error, count=self.failed_reads))
            return None
        if self.failed_reads > self.retries:
            self.report(self.text["again"].format(count=self.failed_reads))
        self.failed_reads = 0
        self.latest_deg = leader_command_deg(present, self._motors)
        return self.latest_deg

    def close(self) -> None:
        """The port closed; torque is not touched (it is off). Safe twice."""
        bus, self.bus = self.bus, None
        if bus is not None:
            bus.close()

    def __enter__(self) -> "SO101Leader":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
