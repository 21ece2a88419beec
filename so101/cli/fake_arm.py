"""`so101 fake-arm`: the emulated SO-101 servo bus (so101/feetech/fake_arm.py) on a pseudo-terminal,
with a command line for a person or a script: a hand that moves the joints (a scripted one makes
it a leader arm that moves by itself: so101/feetech/hand.py), and faults to try."""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import time
import unicodedata
from typing import Any

from so101.runtime.argtypes import add_language_option, number
from so101.feetech import sts3215
from so101.feetech.fake_arm import ALL_IDS, DEFAULT_SPEED_STEPS_S, MECHANICS, FakeArm, Response
from so101.feetech.fake_arm.process import raise_priority
from so101.feetech.hand import FIGURE_EIGHT_EASE_S, FIGURE_EIGHT_PERIOD_S, Keyframes, figure_eight_deg, load_keyframes


COMMANDS_HELP = """\
commands (one per line):
  help               this list
  status             every servo: torque, goal, present position, homing offset, limits, joint
  sweep [SECONDS]    a hand moves every torque-off joint to both stops and back (default 4 s)
  move ID STEPS      a hand moves joint ID to physical encoder position STEPS (torque off only);
                     +STEPS or -STEPS moves it by that much
  figure8 [PERIOD_S] a hand moves every torque-off joint so the tip draws a figure eight, a loop
                     every PERIOD_S (default 8 s), until hold or another hand command: a leader
  play FILE          a hand plays FILE's timed keyframes once and leaves the joints at the last;
                     a line is SECONDS and six angles in degrees (examples/leader_wave.keyframes)
  hold               the hand lets go: every joint stays where it is
  silent ID          servo ID keeps obeying but stops replying
  corrupt ID         servo ID replies with a wrong checksum
  answer ID|all      servo ID (or every servo, mute included) replies normally again
  mute               no servo replies (a broken return line; they all still obey)
  close              the port goes away, as an unplugged USB adapter
  quit               stop the emulator (Ctrl-C and SIGTERM too)"""

ACCEPTED = ("help, status, sweep [SECONDS], move ID STEPS, figure8 [PERIOD_S], play FILE, hold, "
            "silent ID, corrupt ID, answer ID|all, mute, close, quit")

# What the console says, in the session's language (--lang). The commands themselves are the same words in both.
TEXT: dict[str, dict[str, Any]] = {
    "zh": {
        "help": """\
命令(每行一条):
  help               本列表
  status             每个舵机:扭矩、目标、当前位置、零位偏移、限位、关节
  sweep [SECONDS]    一只手把每个扭矩关闭的关节转到两端再转回(默认 4 秒)
  move ID STEPS      一只手把关节 ID 移到物理编码器位置 STEPS(仅扭矩关闭时);
                     +STEPS 或 -STEPS 表示移动这么多步
  figure8 [PERIOD_S] 一只手移动每个扭矩关闭的关节,让末端画 8 字,每 PERIOD_S 秒一圈
                     (默认 8 秒),直到 hold 或另一条手部命令:一个主臂
  play FILE          一只手按 FILE 的定时关键帧播放一次,关节停在最后一帧;
                     每行是秒数和六个角度(度)(examples/leader_wave.keyframes)
  hold               手松开:每个关节停在原处
  silent ID          舵机 ID 继续执行但不再应答
  corrupt ID         舵机 ID 的应答校验和错误
  answer ID|all      舵机 ID(或全部舵机,包括 mute)恢复正常应答
  mute               所有舵机都不应答(回传线断了;它们仍执行命令)
  close              端口消失,如同拔掉 USB 转接器
  quit               停止模拟器(Ctrl-C 和 SIGTERM 也可以)""",
        "about": "模拟的 SO-101 总线:{count} 个 STS3215 舵机,ID {ids},1,000,000 波特;模拟协议和寄存器,"
                 "不模拟物理(无重力、无负载);输入 help 查看命令",
        "response": "舵机在运行中晚 {delay_ms:g} ms 执行新目标,以 {tau_ms:g} ms 的时间常数缩小最后的差距(0:全速到位)",
        "unknown": "未知命令 {word!r};命令:{accepted}",
        "usage": "用法:{usage};命令:{accepted}",
        "no_servo": "总线上没有舵机 {text!r};ID:{ids}",
        "sweep_bad": "sweep 需要一个秒数,大于 0 且不超过 600;收到 {got!r}",
        "sweeping": "正在 {seconds:g} 秒内转动关节 {ids}{note}",
        "sweeping_none": "没有可转动的关节{note}",
        "holds_note": ";扭矩保持 {ids}",
        "move_bad": "move 的 STEPS 是物理位置 0-4095,或 +N / -N 表示移动 N 步;收到 {got!r}",
        "move_held": "舵机 {id} 扭矩开着:保持在 {reached};手推不动它",
        "moved": "舵机 {id} 被手从 {before} 移到 {reached}",
        "figure8_bad": "figure8 需要一个周期(秒),从 {low:g} 到 {high:g};收到 {got!r}",
        "hand_none": "手:没有可移动的关节,扭矩保持 {held}",
        "hand_moves": "手:{what},{ids}{note}(hold 让它停下)",
        "joint": "关节", "joints": "关节",
        "figure_eight": "8 字,每圈 {period:g} 秒",
        "playing": "播放 {name} 一次,{count} {keyframes},共 {seconds:g} 秒",
        "keyframe": "个关键帧", "keyframes": "个关键帧",
        "let_go_one": "手:松开关节 {id},它停在原处",
        "let_go_many": "手:松开关节 {ids},它们停在原处",
        "let_go_none": "手:没有被手移动的关节;它们停在原处",
        "all_answer": "所有舵机恢复正常应答",
        "fault": "舵机 {id}:{state}",
        "states": {"answers": "正常应答", "silent": "不应答", "corrupt": "校验和错误", "muted": "全部静默"},
        "muted": "所有舵机静默:它们执行命令,但都不应答(answer all 撤销)",
        "closed": "端口 {port} 已关闭,如同拔掉转接器;输入 quit 结束",
        "closed_after": "端口 {port} 在 {seconds:g} 秒后关闭,如同拔掉转接器",
        "faults_on": "故障开启:不应答 {silent},校验和错误 {corrupt}",
        "none": "无",
        "not_on_bus": "注意:{ids} 不在此总线上(--ids);它们没有故障",
        "end_of_input": "输入结束:模拟器继续运行,直到 Ctrl-C 或 SIGTERM",
        "calibrating": "此总线上开始了一次校准:当它要求把每个关节转到行程两端时,在这里输入 sweep"
                       "(一只手在 4 秒内把它们带到两端再回来),然后在校准的终端按 Enter",
        "columns": ("关节", "扭矩", "目标", "当前", "偏移", "限位", "物理", "止挡", "应答"),
        "on": "开", "off": "关", "free": "自由",
        "port_closed": "端口 {port} 已关闭(拔掉了):没有主机能访问这些舵机",
    },
    "en": {
        "help": COMMANDS_HELP,
        "about": "an emulated SO-101 bus: {count} STS3215 servos, ids {ids}, 1,000,000 baud; it emulates the protocol "
                 "and the registers, not the physics (no gravity, no load); type help for its commands",
        "response": "its servos act on a new goal {delay_ms:g} ms late while they run, and close the last of a gap "
                    "with a {tau_ms:g} ms time constant (0: at top speed)",
        "unknown": "unknown command {word!r}; commands: {accepted}",
        "usage": "usage: {usage}; commands: {accepted}",
        "no_servo": "no servo {text!r} on this bus; ids: {ids}",
        "sweep_bad": "sweep takes a duration in seconds, more than 0 and at most 600; got {got!r}",
        "sweeping": "sweeping {ids} over {seconds:g} s{note}",
        "sweeping_none": "sweeping no joint{note}",
        "holds_note": "; torque holds {ids}",
        "move_bad": "move takes STEPS as a physical position 0-4095, or +N / -N to move by N steps; got {got!r}",
        "move_held": "servo {id} has torque on: it holds at {reached}; the hand cannot move it",
        "moved": "servo {id} moved by hand from {before} to {reached}",
        "figure8_bad": "figure8 takes a period in seconds, from {low:g} to {high:g}; got {got!r}",
        "hand_none": "hand: no joint to move, torque holds {held}",
        "hand_moves": "hand: {what}, {ids}{note} (hold stops it)",
        "joint": "joint", "joints": "joints",
        "figure_eight": "figure eight, {period:g} s a loop",
        "playing": "playing {name} once, {count} {keyframes} over {seconds:g} s",
        "keyframe": "keyframe", "keyframes": "keyframes",
        "let_go_one": "hand: let go of joint {id} where it stands",
        "let_go_many": "hand: let go of joints {ids} where they stand",
        "let_go_none": "hand: no joint was moving by hand; they stand where they are",
        "all_answer": "every servo replies normally",
        "fault": "servo {id}: {state}",
        "states": {"answers": "answers", "silent": "silent", "corrupt": "corrupt", "muted": "muted"},
        "muted": "every servo muted: they obey, none replies (answer all undoes it)",
        "closed": "port {port} closed, as an unplugged adapter; quit to end",
        "closed_after": "port {port} closed after {seconds:g} s, as an unplugged adapter",
        "faults_on": "faults on: silent {silent}, corrupt {corrupt}",
        "none": "none",
        "not_on_bus": "note: {ids} not on this bus (--ids); no fault for them",
        "end_of_input": "end of input: the emulator keeps running until Ctrl-C or SIGTERM",
        "calibrating": "a calibration has begun on this bus: when it asks you to move every joint to both ends of "
                       "its travel, type sweep here (a hand takes them there and back in 4 s), then press Enter in "
                       "the calibration's terminal",
        "columns": ("joint", "torque", "goal", "present", "offset", "limits", "physical", "stops", "replies"),
        "on": "on", "off": "off", "free": "free",
        "port_closed": "port {port} is closed (unplugged): no host can reach these servos",
    },
}


def _ids(text: str) -> tuple[int, ...]:
    ids: list[int] = []
    try:
        for part in text.split(","):
            if "-" in part:
                first, last = (int(value) for value in part.split("-", 1))
                ids.extend(range(first, last + 1))
            else:
                ids.append(int(part))
    except ValueError:
        ids = []
    if not ids or len(set(ids)) != len(ids) or any(i not in MECHANICS for i in ids):
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a set of servo ids: use distinct ids from 1 to 6, like 1,2,3,4,5,6 or 1-6"
        )
    return tuple(ids)


def _servo_id(text: str) -> int:
    if text not in {str(i) for i in ALL_IDS}:
        raise argparse.ArgumentTypeError(f"{text!r} is not a servo id: use 1 to 6")
    return int(text)


_seconds = number(lambda value: 0 <= value < 1e6, "a time: use seconds, 0 or more")
_response_ms = number(lambda value: 0 <= value <= 2000, "a number of milliseconds from 0 to 2000")
_speed = number(lambda value: 0 < value <= 100_000,
                 "a speed: use steps per second, more than 0 (the default is 3000)")
# A figure eight faster than a loop a second is no hand's; slower than 10 minutes looks still.
MIN_PERIOD_S, MAX_PERIOD_S = 1.0, 600.0
FIGURE_EIGHT = "figure8"
PROMPT = "fake-arm> "


def _hand_script(text: str) -> tuple[str, Keyframes | None]:
    """--hand: figure8 (no keyframes), or a keyframe file read now, so a bad one stops the start in one line."""
    if text == FIGURE_EIGHT:
        return text, None
    try:
        return text, load_keyframes(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(f"{error} (--hand takes {FIGURE_EIGHT} or a keyframe file)") from None


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = (
        "The first line printed is the port alone (e.g. /dev/pts/7), for `so101 fake-arm | head -1`\n"
        "or a script; open it at 1,000,000 baud as the arm's serial port. Then type commands.\n"
        "End of input does not stop the emulator; quit, Ctrl-C or SIGTERM does.\n"
        "As a leader arm: --hand figure8 starts it moving (the same as typing figure8).\n\n" + COMMANDS_HELP
    )
    parser.add_argument(
        "--ids", type=_ids, default=ALL_IDS, metavar="IDS",
        help="which servos are on the bus, e.g. 1,2,3,4,5,6 (the default) or 1-3; "
        "1 shoulder_pan, 2 shoulder_lift, 3 elbow_flex, 4 wrist_flex, 5 wrist_roll, 6 gripper",
    )
    parser.add_argument(
        "--speed", type=_speed, default=DEFAULT_SPEED_STEPS_S, metavar="STEPS_PER_S",
        help="the motors' top speed in encoder steps per second, used when Goal_Velocity is 0 "
        "(default 3000 ≈ 264°/s, an STS3215's no-load speed at 7.4 V)",
    )
    parser.add_argument(
        "--delay-ms", type=_response_ms, default=0.0, metavar="MS",
        help="each servo acts on a new goal this late while it runs, as a real follower trails its commands "
        "(about 130 on a LeRobot recording); default 0",
    )
    parser.add_argument(
        "--time-constant-ms", type=_response_ms, default=0.0, metavar="MS",
        help="each servo closes the last of a gap with this time constant, as a P loop does; default 0: "
        "at top speed right onto the goal",
    )
    parser.add_argument(
        "--hand", type=_hand_script, default=None, metavar="figure8|FILE",
        help="a hand starts moving the joints at once, as the figure8 or play FILE command does: "
        "an emulated leader arm already moving, for a script",
    )
    parser.add_argument(
        "--silent", type=_servo_id, action="append", default=[], metavar="ID",
        help="servo ID obeys but never replies (repeatable)",
    )
    parser.add_argument(
        "--corrupt", type=_servo_id, action="append", default=[], metavar="ID",
        help="servo ID replies with a wrong checksum (repeatable)",
    )
    parser.add_argument(
        "--fault-after", type=_seconds, default=0.0, metavar="SECONDS",
        help="start the --silent/--corrupt faults this long after start-up (default 0: from the start)",
    )
    parser.add_argument(
        "--close-after", type=_seconds, default=None, metavar="SECONDS",
        help="close the port this long after start-up, as an unplugged USB adapter (the emulator keeps running)",
    )
    add_language_option(parser, "the console's replies")


class _Stop(Exception):
    """SIGTERM, turned into an exception in the main thread."""


class _Output:
    """Lines for a person; a reader that went away (`| head -1`) silences it, not the emulator."""

    def __init__(self, prompt: str = "") -> None:
        self._lock = threading.Lock()
        self._gone = False
        self.prompt = prompt  # shown again after a line that came while a person was at it

    def say(self, text: str) -> None:
        self._print(text)

    def say_aside(self, text: str) -> None:
        """A line the emulator says by itself (a calibration noticed, a timed fault), on a line of its own."""
        self._print(f"\n{text}\n{self.prompt}" if self.prompt else text, end="" if self.prompt else "\n")

    def _print(self, text: str, end: str = "\n") -> None:
        with self._lock:
            if self._gone:
                return
            try:
                print(text, end=end, flush=True)
            except (BrokenPipeError, ValueError, OSError):
                self._gone = True
                try:  # later writes (and the interpreter's own flush at exit) go nowhere
                    null = os.open(os.devnull, os.O_WRONLY)
                    os.dup2(null, sys.stdout.fileno())
                    os.close(null)
                except (OSError, ValueError):
                    pass


def _padded(text: str, width: int, right: bool = False) -> str:
    """`text` padded to `width` terminal columns (a Chinese character takes two)."""
    room = " " * max(0, width - sum(2 if unicodedata.east_asian_width(c) in "WF" else 1 for c in text))
    return room + text if right else text + room


def _status_table(arm: FakeArm, text: dict) -> str:
    def span(pair) -> str:
        return text["free"] if pair[0] is None else f"{pair[0]}..{pair[1]}"

    joint, torque, goal, present, offset, limits, physical, stops, replies = text["columns"]
    lines = [
        f"{'id':>2}  {_padded(joint, 13)} {_padded(torque, 6)} {_padded(goal, 5, True)} {_padded(present, 7, True)} "
        f"{_padded(offset, 6, True)}  {_padded(limits, 9)}  {_padded(physical, 8, True)}  {_padded(stops, 10)}  {replies}"
    ]
    for row in arm.status_rows():
        ident = str(row["id"]) if row["bus_id"] == row["id"] else f"{row['id']}>{row['bus_id']}"
        lines.append(
            f"{ident:>2}  {row['joint']:<13} {_padded(text['on'] if row['torque'] else text['off'], 6)} {row['goal']:>5} "
            f"{row['present']:>7} {row['homing_offset']:>6}  {_padded(span(row['limits']), 9)}  {row['physical']:>8}  "
            f"{_padded(span(row['stops']), 10)}  {text['states'][row['replies']]}"
        )
    if not arm.port_open:
        lines.append(text["port_closed"].format(port=arm.port))
    return "\n".join(lines)


def _ids_text(ids) -> str:
    """Servo ids as a person writes them: "1-6", "1, 3-6"."""
    runs: list[list[int]] = []
    for servo_id in sorted(ids):
        if runs and servo_id == runs[-1][-1] + 1:
            runs[-1].append(servo_id)
        else:
            runs.append([servo_id])
    return ", ".join(f"{run[0]}-{run[-1]}" if len(run) > 2 else ", ".join(map(str, run)) for run in runs)


def _hand_reply(arm: FakeArm, what: str, moved: tuple[int, ...], text: dict) -> str:
    held = [servo_id for servo_id in arm.ids if servo_id not in moved]
    if not moved:
        return text["hand_none"].format(held=_ids_text(held))
    note = text["holds_note"].format(ids=_ids_text(held)) if held else ""
    joints = text["joints" if len(moved) > 1 else "joint"]
    return text["hand_moves"].format(what=what, ids=f"{joints} {_ids_text(moved)}", note=note)


def _play_figure_eight(arm: FakeArm, period_s: float, text: dict) -> str:
    moved = arm.play_hand(lambda t_s: figure_eight_deg(t_s, period_s), None, ease_s=FIGURE_EIGHT_EASE_S)
    return _hand_reply(arm, text["figure_eight"].format(period=period_s), moved, text)


def _play_keyframes(arm: FakeArm, keyframes: Keyframes, name: str, text: dict) -> str:
    # The hand reaches the first keyframe at its time, from where the joints stand (at once if it is 0).
    moved = arm.play_hand(keyframes.at, keyframes.duration_s, ease_s=keyframes.times_s[0])
    count = len(keyframes.times_s)
    what = text["playing"].format(name=name, count=count, keyframes=text["keyframes" if count > 1 else "keyframe"],
                                  seconds=keyframes.duration_s)
    return _hand_reply(arm, what, moved, text)


def _command(arm: FakeArm, line: str, say, text: dict) -> bool:
    """Carry out one typed command, replying in `text`'s language; False for quit."""
    words = line.split()
    if not words:
        return True
    verb, rest = words[0].lower(), words[1:]

    def servo_of(typed: str) -> int | None:
        if typed.isdigit() and int(typed) in arm.ids:
            return int(typed)
        say(text["no_servo"].format(text=typed, ids=", ".join(map(str, arm.ids))))
        return None

    def wrong_arguments(usage: str) -> bool:
        say(text["usage"].format(usage=verb + (" " + usage if usage else ""), accepted=ACCEPTED))
        return True

    if verb in ("quit", "exit"):
        return False
    if verb == "help":
        say(text["help"])
    elif verb == "status":
        say(_status_table(arm, text))
    elif verb == "sweep":
        if len(rest) > 1:
            return wrong_arguments("[SECONDS]")
        try:
            duration = float(rest[0]) if rest else 4.0
        except ValueError:
            duration = float("nan")
        if not 0 < duration <= 600:
            say(text["sweep_bad"].format(got=rest[0]))
            return True
        swept = arm.sweep(duration)
        held = [i for i in arm.ids if i not in swept]
        note = text["holds_note"].format(ids=", ".join(map(str, held))) if held else ""
        if swept:
            say(text["sweeping"].format(ids=", ".join(map(str, swept)), seconds=duration, note=note))
        else:
            say(text["sweeping_none"].format(note=note))
    elif verb == "move":
        if len(rest) != 2:
            return wrong_arguments("ID STEPS")
        servo_id = servo_of(rest[0])
        if servo_id is None:
            return True
        steps = rest[1]
        relative = steps[:1] in "+-"
        digits = steps[1:] if relative else steps
        if not digits.isdigit() or (not relative and int(digits) > sts3215.MAX_STEP):
            say(text["move_bad"].format(got=steps))
            return True
        before = arm.physical_position(servo_id)
        reached = arm.move_by_hand(servo_id, int(steps), relative=relative)
        if arm.read_register(servo_id, "Torque_Enable"):
            say(text["move_held"].format(id=servo_id, reached=reached))
        else:
            say(text["moved"].format(id=servo_id, before=before, reached=reached))
    elif verb == FIGURE_EIGHT:
        if len(rest) > 1:
            return wrong_arguments("[PERIOD_S]")
        try:
            period_s = float(rest[0]) if rest else FIGURE_EIGHT_PERIOD_S
        except ValueError:
            period_s = float("nan")
        if not MIN_PERIOD_S <= period_s <= MAX_PERIOD_S:
            say(text["figure8_bad"].format(low=MIN_PERIOD_S, high=MAX_PERIOD_S, got=rest[0]))
            return True
        say(_play_figure_eight(arm, period_s, text))
    elif verb == "play":
        name = line.strip()[len(words[0]):].strip()  # the rest as typed: a file name may hold spaces
        if not name:
            return wrong_arguments("FILE")
        try:
            keyframes = load_keyframes(name)
        except ValueError as error:
            say(str(error))
            return True
        say(_play_keyframes(arm, keyframes, name, text))
    elif verb == "hold":
        if rest:
            return wrong_arguments("")
        let_go = arm.stop_hand()
        if len(let_go) == 1:
            say(text["let_go_one"].format(id=let_go[0]))
        elif let_go:
            say(text["let_go_many"].format(ids=_ids_text(let_go)))
        else:
            say(text["let_go_none"])
    elif verb in ("silent", "corrupt", "answer"):
        if len(rest) != 1:
            return wrong_arguments("ID" if verb != "answer" else "ID|all")
        if verb == "answer" and rest[0].lower() == "all":
            arm.answer_all()
            say(text["all_answer"])
            return True
        servo_id = servo_of(rest[0])
        if servo_id is None:
            return True
        {"silent": arm.silence, "corrupt": arm.corrupt, "answer": arm.answer}[verb](servo_id)
        say(text["fault"].format(id=servo_id, state=text["states"][arm.faults()[servo_id]]))
    elif verb == "mute":
        arm.mute_all()
        say(text["muted"])
    elif verb == "close":
        arm.close_port()
        say(text["closed"].format(port=arm.port))
    else:
        say(text["unknown"].format(word=words[0], accepted=ACCEPTED))
    return True


def run(args: argparse.Namespace) -> int:
    def stop(signum, frame):
        raise _Stop

    previous = signal.signal(signal.SIGTERM, stop)
    interactive = sys.stdin is not None and sys.stdin.isatty()
    out = _Output(PROMPT if interactive else "")
    timers: list[threading.Timer] = []
    text = TEXT[args.lang]
    arm = FakeArm(ids=args.ids, speed_steps_s=args.speed,
                  response=Response(delay_s=args.delay_ms / 1000, time_constant_s=args.time_constant_ms / 1000))
    raise_priority()  # the servos' stand-in: a busy machine should starve the driver, not the servos

    def faults() -> None:
        for servo_id in args.silent:
            if servo_id in arm.ids:
                arm.silence(servo_id)
        for servo_id in args.corrupt:
            if servo_id in arm.ids:
                arm.corrupt(servo_id)
        if args.fault_after:
            out.say_aside(text["faults_on"].format(silent=", ".join(map(str, args.silent)) or text["none"],
                                                   corrupt=", ".join(map(str, args.corrupt)) or text["none"]))

    if not args.fault_after:
        # Before the port is served: a driver that opens it as soon as it is printed meets the faults already on
        # (on a busy machine it once pinged --silent 6 before they were, and 6 answered).
        faults()
    arm.on_calibration = lambda: out.say_aside(text["calibrating"])
    arm.start()
    try:
        out.say(arm.port)
        out.say(text["about"].format(count=len(arm.ids), ids=", ".join(map(str, arm.ids))))
        if args.delay_ms or args.time_constant_ms:
            out.say(text["response"].format(delay_ms=args.delay_ms, tau_ms=args.time_constant_ms))

        def unplug() -> None:
            arm.close_port()
            out.say_aside(text["closed_after"].format(port=arm.port, seconds=args.close_after))

        if args.hand is not None:
            name, keyframes = args.hand
            if keyframes is None:
                out.say(_play_figure_eight(arm, FIGURE_EIGHT_PERIOD_S, text))
            else:
                out.say(_play_keyframes(arm, keyframes, name, text))

        missing = [i for i in args.silent + args.corrupt if i not in arm.ids]
        if missing:
            out.say(text["not_on_bus"].format(ids=", ".join(map(str, missing))))
        if (args.silent or args.corrupt) and args.fault_after:
            timers.append(threading.Timer(args.fault_after, faults))
        if args.close_after is not None:
            timers.append(threading.Timer(args.close_after, unplug))
        for timer in timers:
            timer.daemon = True
            timer.start()

        while True:
            if interactive:
                print(PROMPT, end="", flush=True)
            line = sys.stdin.readline() if sys.stdin is not None else ""
            if not line:
                out.say(text["end_of_input"])
                while True:
                    time.sleep(3600)
            if not _command(arm, line, out.say, text):
                break
    except (KeyboardInterrupt, _Stop):
        pass
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # a second SIGTERM must not interrupt the clean-up
        for timer in timers:
            timer.cancel()
        arm.close()
        signal.signal(signal.SIGTERM, previous)
    return 0
