"""`so101 calibrate`: calibrate an SO-101 follower arm (or, with --leader, a leader arm) without LeRobot,
into LeRobot's JSON format.

The steps LeRobot's `lerobot-calibrate` takes for the so101_follower and the so101_leader alike: torque off; the
person puts the arm in the middle of its range and presses Enter, and each servo's
Homing_Offset is set so that it reads mid-scale (2047) there; the person moves every
joint but wrist_roll to both ends of its travel and presses Enter, while the positions
are read and the extremes kept; wrist_roll turns fully, so its range is the whole turn.
The offsets and ranges go into the servos (Homing_Offset, Min/Max_Position_Limit) and
into the file. Nothing is written to the file until the end; an existing file is kept
as FILE.bak when --force replaces it. Torque is only ever switched off, so a leader's never goes on.
"""

from __future__ import annotations

import argparse
import os
import select
import shutil
import sys
from pathlib import Path

from so101.runtime.argtypes import add_language_option
from so101.feetech.calibration import (
    MIN_RANGE_STEPS,
    MOTOR_IDS,
    MOTOR_NAMES,
    MotorCalibration,
    homing_offset,
    save_calibration,
)
from so101.feetech.bus import BusError, FeetechBus, ServoSilent
from so101.feetech.checks import check_servos_answer
from so101.feetech.sts3215 import MAX_STEP, SIGN_BITS, STEPS_PER_TURN, encode_signed

FULL_TURN_JOINT = "wrist_roll"
POLL_S = 0.01  # how often positions are read while the person moves the joints
WRITE_TRIES = 3

TEXT = {
    "zh": {
        "middle": "扭矩已关闭。用手把机械臂摆到行程中间:大臂竖直向上,小臂和夹爪水平朝前,夹爪半开"
                  "(课程的初始姿态:`so101 snapshot` 会画出来)。然后按 Enter。",
        "ends": "现在把除 {full_turn} 以外的每个关节逐一慢慢转到行程的两端。完成后按 Enter。",
        "short": "{names} 转动不足 {steps} 步({deg:.0f}°):把它们各自转到两端,再按 Enter(Ctrl-C 放弃,不写任何东西)。",
        "exists": "{out} 已存在:加 --force 覆盖(旧文件保留为 {backup})",
        "folder": "{out} 是文件夹:--out 需要一个文件名",
        "bus": "{error};没有写入 {out}",
        "interrupted": "已中断;没有写入 {out}",
        "ended": "输入在校准完成前结束;没有写入 {out}",
        "wrote": "已写入 {out}:",
        "motor": "  {name:<14} id {id}  homing_offset {offset:>5}  范围 {low:>4}..{high:<4} ({span:.0f}°)",
        "use": "使用它:{command}",
    },
    "en": {
        "middle": "Torque is off. Move the arm by hand to the middle of its range: the upper arm straight up, "
                  "the forearm and the gripper level, pointing forward, the gripper half open "
                  "(the course's home pose: `so101 snapshot` draws it). Then press Enter.",
        "ends": "Now move every joint except {full_turn} slowly to both ends of its travel, one at a time. "
                "Press Enter when done.",
        "short": "{names} moved less than {steps} steps ({deg:.0f}°): "
                 "move each to both of its ends, then press Enter (Ctrl-C gives up, nothing is written).",
        "exists": "{out} exists: pass --force to replace it (the old one is kept as {backup})",
        "folder": "{out} is a folder: --out takes a file name",
        "bus": "{error}; nothing was written to {out}",
        "interrupted": "interrupted; nothing was written to {out}",
        "ended": "the input ended before the calibration did; nothing was written to {out}",
        "wrote": "Wrote {out}:",
        "motor": "  {name:<14} id {id}  homing_offset {offset:>5}  range {low:>4}..{high:<4} ({span:.0f}°)",
        "use": "Use it: {command}",
    },
}


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    parser.add_argument("--port", required=True, metavar="PORT",
                        help="the arm's serial port (/dev/ttyACM0, ...; `so101 fake-arm` prints an emulated one)")
    parser.add_argument("--out", required=True, type=Path, metavar="FILE",
                        help="where to write the calibration (LeRobot's so101_follower JSON format; so101_leader's with --leader)")
    parser.add_argument("--leader", action="store_true",
                        help="the arm on PORT is a leader arm (torque stays off; the file is LeRobot's so101_leader one)")
    parser.add_argument("--force", action="store_true",
                        help="replace FILE if it exists (the old one is kept as FILE.bak)")
    add_language_option(parser, "the instructions")


def _say(line: str = "", end: str = "\n") -> None:
    print(line, end=end, flush=True)


class _Lines:
    """Lines typed on stdin, read from its file descriptor so select() sees every one
    (Python's buffered reader could hold a second line where select cannot see it)."""

    def __init__(self):
        self._pending = b""

    def wait_for_enter(self, poll=None) -> bool:
        """Block until a line is typed; call `poll()` meanwhile. False on end of input."""
        while b"\n" not in self._pending:
            ready, _, _ = select.select([sys.stdin], [], [], POLL_S)
            if ready:
                chunk = os.read(sys.stdin.fileno(), 1024)
                if not chunk:
                    return False
                self._pending += chunk
            elif poll is not None:
                poll()
        self._pending = self._pending.split(b"\n", 1)[1]
        return True


def _write_eeprom(bus: FeetechBus, name: str, values: dict[int, int]) -> None:
    """Each write acknowledged, each tried up to WRITE_TRIES times: one lost reply must not end a
    calibration (writing the same value again is harmless)."""
    for servo_id, value in values.items():
        for attempt in range(WRITE_TRIES):
            try:
                bus.write(servo_id, name, value)
                break
            except ServoSilent:
                if attempt == WRITE_TRIES - 1:
                    raise


def calibrate(bus: FeetechBus, lang: str = "en") -> dict[str, MotorCalibration] | None:
    """The interactive steps on an open bus, told in `lang`; the calibration, or None if the input ended first."""
    text = TEXT[lang]
    check_servos_answer(bus)
    lines = _Lines()
    everyone = dict.fromkeys(MOTOR_IDS, 0)
    bus.sync_write("Torque_Enable", everyone)
    _write_eeprom(bus, "Lock", everyone)  # unlocked: the offsets and limits must persist
    _write_eeprom(bus, "Homing_Offset", everyone)
    _write_eeprom(bus, "Min_Position_Limit", everyone)
    _write_eeprom(bus, "Max_Position_Limit", dict.fromkeys(MOTOR_IDS, MAX_STEP))

    _say(text["middle"])
    if not lines.wait_for_enter():
        return None
    raw = bus.sync_read("Present_Position", MOTOR_IDS)
    offsets = {servo_id: homing_offset(raw[servo_id]) for servo_id in MOTOR_IDS}
    _write_eeprom(bus, "Homing_Offset", {i: encode_signed(offset, SIGN_BITS["Homing_Offset"]) for i, offset in offsets.items()})

    ranged = [(name, servo_id) for name, servo_id in zip(MOTOR_NAMES, MOTOR_IDS) if name != FULL_TURN_JOINT]
    low = bus.sync_read("Present_Position", MOTOR_IDS)
    high = dict(low)

    shown = [""]

    def record() -> None:
        try:
            present = bus.sync_read("Present_Position", MOTOR_IDS)
        except ServoSilent:
            return  # this poll is lost; the next one, 10 ms later, reads the same joints
        for servo_id, position in present.items():
            low[servo_id] = min(low[servo_id], position)
            high[servo_id] = max(high[servo_id], position)
        # How far each joint has travelled, redrawn in place (one terminal row) when it grows.
        line = " ".join(f"{name} {(high[i] - low[i]) * 360 / STEPS_PER_TURN:.0f}°" for name, i in ranged)
        line = line[: shutil.get_terminal_size().columns - 1]
        if sys.stdout.isatty() and line != shown[0]:
            _say("\r\x1b[K" + line, end="")
            shown[0] = line

    _say(text["ends"].format(full_turn=FULL_TURN_JOINT))
    while True:
        if not lines.wait_for_enter(record):
            return None
        short = [name for name, servo_id in ranged if high[servo_id] - low[servo_id] < MIN_RANGE_STEPS]
        if not short:
            break
        _say("\n" + text["short"].format(names=", ".join(short), steps=MIN_RANGE_STEPS,
                                         deg=MIN_RANGE_STEPS * 360 / STEPS_PER_TURN))

    calibration = {}
    for name, servo_id in zip(MOTOR_NAMES, MOTOR_IDS):
        range_min, range_max = (0, MAX_STEP) if name == FULL_TURN_JOINT else (low[servo_id], high[servo_id])
        calibration[name] = MotorCalibration(servo_id, 0, offsets[servo_id], range_min, range_max)
    _write_eeprom(bus, "Min_Position_Limit", {m.id: m.range_min for m in calibration.values()})
    _write_eeprom(bus, "Max_Position_Limit", {m.id: m.range_max for m in calibration.values()})
    _write_eeprom(bus, "Lock", dict.fromkeys(MOTOR_IDS, 1))
    return calibration


def run(args: argparse.Namespace) -> int:
    text = TEXT[args.lang]
    out = args.out.expanduser()

    def refuse(key: str, after_prompts: bool = False, **values) -> None:
        # Once the instructions have started, on a line of its own (the travel shown may end without one).
        print("\n" * after_prompts + "so101 calibrate: " + text[key].format(out=out, **values), file=sys.stderr)

    if out.exists() and not args.force:
        refuse("exists", backup=f"{out.name}.bak")
        return 2
    if out.is_dir():
        refuse("folder")
        return 2
    bus = FeetechBus(args.port)
    try:
        bus.open()
        calibration = calibrate(bus, args.lang)
    except BusError as error:
        refuse("bus", True, error=error)
        return 1
    except KeyboardInterrupt:
        refuse("interrupted", True)
        return 130
    finally:
        bus.close()
    if calibration is None:
        refuse("ended", True)
        return 1
    if out.exists():
        out.replace(out.with_name(out.name + ".bak"))
    save_calibration(out, calibration)
    _say("\n" + text["wrote"].format(out=out))
    for name, motor in calibration.items():
        _say(text["motor"].format(name=name, id=motor.id, offset=motor.homing_offset, low=motor.range_min,
                                  high=motor.range_max, span=(motor.range_max - motor.range_min) * 360 / STEPS_PER_TURN))
    if args.leader:
        command = f"so101 teleop --leader {args.port} --leader-calibration {out}"
    else:
        command = f"so101 teleop --body real --port {args.port} --calibration {out}"
    _say(text["use"].format(command=command))
    return 0
