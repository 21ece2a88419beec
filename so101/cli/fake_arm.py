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

from so101.cli.argtypes import number
from so101.feetech import sts3215
from so101.feetech.fake_arm import ALL_IDS, DEFAULT_SPEED_STEPS_S, MECHANICS, FakeArm
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
_speed = number(lambda value: 0 < value <= 100_000,
                 "a speed: use steps per second, more than 0 (the default is 3000)")
# A figure eight faster than a loop a second is no hand's; slower than 10 minutes looks still.
MIN_PERIOD_S, MAX_PERIOD_S = 1.0, 600.0
FIGURE_EIGHT = "figure8"


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


class _Stop(Exception):
    """SIGTERM, turned into an exception in the main thread."""


class _Output:
    """Lines for a person; a reader that went away (`| head -1`) silences it, not the emulator."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._gone = False

    def say(self, text: str) -> None:
        with self._lock:
            if self._gone:
                return
            try:
                print(text, flush=True)
            except (BrokenPipeError, ValueError, OSError):
                self._gone = True
                try:  # later writes (and the interpreter's own flush at exit) go nowhere
                    null = os.open(os.devnull, os.O_WRONLY)
                    os.dup2(null, sys.stdout.fileno())
                    os.close(null)
                except (OSError, ValueError):
                    pass


def _status_table(arm: FakeArm) -> str:
    def span(pair) -> str:
        return "free" if pair[0] is None else f"{pair[0]}..{pair[1]}"

    lines = [
        f"{'id':>2}  {'joint':<13} {'torque':<6} {'goal':>5} {'present':>7} {'offset':>6}  "
        f"{'limits':<9}  {'physical':>8}  {'stops':<10}  replies"
    ]
    for row in arm.status_rows():
        ident = str(row["id"]) if row["bus_id"] == row["id"] else f"{row['id']}>{row['bus_id']}"
        lines.append(
            f"{ident:>2}  {row['joint']:<13} {'on' if row['torque'] else 'off':<6} {row['goal']:>5} "
            f"{row['present']:>7} {row['homing_offset']:>6}  {span(row['limits']):<9}  {row['physical']:>8}  "
            f"{span(row['stops']):<10}  {row['replies']}"
        )
    if not arm.port_open:
        lines.append(f"port {arm.port} is closed (unplugged): no host can reach these servos")
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


def _hand_reply(arm: FakeArm, what: str, moved: tuple[int, ...]) -> str:
    held = [servo_id for servo_id in arm.ids if servo_id not in moved]
    if not moved:
        return f"hand: no joint to move, torque holds {_ids_text(held)}"
    note = f"; torque holds {_ids_text(held)}" if held else ""
    return f"hand: {what}, joint{'s' if len(moved) > 1 else ''} {_ids_text(moved)}{note} (hold stops it)"


def _play_figure_eight(arm: FakeArm, period_s: float) -> str:
    moved = arm.play_hand(lambda t_s: figure_eight_deg(t_s, period_s), None, ease_s=FIGURE_EIGHT_EASE_S)
    return _hand_reply(arm, f"figure eight, {period_s:g} s a loop", moved)


def _play_keyframes(arm: FakeArm, keyframes: Keyframes, name: str) -> str:
    # The hand reaches the first keyframe at its time, from where the joints stand (at once if it is 0).
    moved = arm.play_hand(keyframes.at, keyframes.duration_s, ease_s=keyframes.times_s[0])
    count = len(keyframes.times_s)
    return _hand_reply(
        arm, f"playing {name} once, {count} keyframe{'s' if count > 1 else ''} over {keyframes.duration_s:g} s", moved
    )


def _command(arm: FakeArm, line: str, say) -> bool:
    """Carry out one typed command; False for quit."""
    words = line.split()
    if not words:
        return True
    verb, rest = words[0].lower(), words[1:]
    accepted = (
        "help, status, sweep [SECONDS], move ID STEPS, figure8 [PERIOD_S], play FILE, hold, "
        "silent ID, corrupt ID, answer ID|all, mute, close, quit"
    )

    def servo_of(text: str) -> int | None:
        if text.isdigit() and int(text) in arm.ids:
            return int(text)
        say(f"no servo {text!r} on this bus; ids: {', '.join(map(str, arm.ids))}")
        return None

    def wrong_arguments(usage: str) -> bool:
        say(f"usage: {verb}{' ' + usage if usage else ''}; commands: {accepted}")
        return True

    if verb in ("quit", "exit"):
        return False
    if verb == "help":
        say(COMMANDS_HELP)
    elif verb == "status":
        say(_status_table(arm))
    elif verb == "sweep":
        if len(rest) > 1:
            return wrong_arguments("[SECONDS]")
        try:
            duration = float(rest[0]) if rest else 4.0
        except ValueError:
            duration = float("nan")
        if not 0 < duration <= 600:
            say(f"sweep takes a duration in seconds, more than 0 and at most 600; got {rest[0]!r}")
            return True
        swept = arm.sweep(duration)
        held = [i for i in arm.ids if i not in swept]
        note = f"; torque holds {', '.join(map(str, held))}" if held else ""
        say(f"sweeping {', '.join(map(str, swept)) or 'no joint'} over {duration:g} s{note}")
    elif verb == "move":
        if len(rest) != 2:
            return wrong_arguments("ID STEPS")
        servo_id = servo_of(rest[0])
        if servo_id is None:
            return True
        text = rest[1]
        relative = text[:1] in "+-"
        digits = text[1:] if relative else text
        if not digits.isdigit() or (not relative and int(digits) > sts3215.MAX_STEP):
            say(f"move takes STEPS as a physical position 0-4095, or +N / -N to move by N steps; got {text!r}")
            return True
        before = arm.physical_position(servo_id)
        reached = arm.move_by_hand(servo_id, int(text), relative=relative)
        if arm.read_register(servo_id, "Torque_Enable"):
            say(f"servo {servo_id} has torque on: it holds at {reached}; the hand cannot move it")
        else:
            say(f"servo {servo_id} moved by hand from {before} to {reached}")
    elif verb == FIGURE_EIGHT:
        if len(rest) > 1:
            return wrong_arguments("[PERIOD_S]")
        try:
            period_s = float(rest[0]) if rest else FIGURE_EIGHT_PERIOD_S
        except ValueError:
            period_s = float("nan")
        if not MIN_PERIOD_S <= period_s <= MAX_PERIOD_S:
            say(f"figure8 takes a period in seconds, from {MIN_PERIOD_S:g} to {MAX_PERIOD_S:g}; got {rest[0]!r}")
            return True
        say(_play_figure_eight(arm, period_s))
    elif verb == "play":
        name = line.strip()[len(words[0]):].strip()  # the rest as typed: a file name may hold spaces
        if not name:
            return wrong_arguments("FILE")
        try:
            keyframes = load_keyframes(name)
        except ValueError as error:
            say(str(error))
            return True
        say(_play_keyframes(arm, keyframes, name))
    elif verb == "hold":
        if rest:
            return wrong_arguments("")
        let_go = arm.stop_hand()
        if len(let_go) == 1:
            say(f"hand: let go of joint {let_go[0]} where it stands")
        elif let_go:
            say(f"hand: let go of joints {_ids_text(let_go)} where they stand")
        else:
            say("hand: no joint was moving by hand; they stand where they are")
    elif verb in ("silent", "corrupt", "answer"):
        if len(rest) != 1:
            return wrong_arguments("ID" if verb != "answer" else "ID|all")
        if verb == "answer" and rest[0].lower() == "all":
            arm.answer_all()
            say("every servo replies normally")
            return True
        servo_id = servo_of(rest[0])
        if servo_id is None:
            return True
        {"silent": arm.silence, "corrupt": arm.corrupt, "answer": arm.answer}[verb](servo_id)
        say(f"servo {servo_id}: {arm.faults()[servo_id]}")
    elif verb == "mute":
        arm.mute_all()
        say("every servo muted: they obey, none replies (answer all undoes it)")
    elif verb == "close":
        arm.close_port()
        say(f"port {arm.port} closed, as an unplugged adapter; quit to end")
    else:
        say(f"unknown command {words[0]!r}; commands: {accepted}")
    return True


def run(args: argparse.Namespace) -> int:
    def stop(signum, frame):
        raise _Stop

    previous = signal.signal(signal.SIGTERM, stop)
    out = _Output()
    timers: list[threading.Timer] = []
    arm = FakeArm(ids=args.ids, speed_steps_s=args.speed).start()
    try:
        out.say(arm.port)
        out.say(
            f"an emulated SO-101 bus: {len(arm.ids)} STS3215 servos, ids {', '.join(map(str, arm.ids))}, "
            f"1,000,000 baud; it emulates the protocol and the registers, not the physics (no gravity, "
            f"no load); type help for its commands"
        )

        def faults() -> None:
            for servo_id in args.silent:
                if servo_id in arm.ids:
                    arm.silence(servo_id)
            for servo_id in args.corrupt:
                if servo_id in arm.ids:
                    arm.corrupt(servo_id)
            if args.fault_after:
                out.say(f"faults on: silent {args.silent or 'none'}, corrupt {args.corrupt or 'none'}")

        def unplug() -> None:
            arm.close_port()
            out.say(f"port {arm.port} closed after {args.close_after:g} s, as an unplugged adapter")

        if args.hand is not None:
            name, keyframes = args.hand
            if keyframes is None:
                out.say(_play_figure_eight(arm, FIGURE_EIGHT_PERIOD_S))
            else:
                out.say(_play_keyframes(arm, keyframes, name))

        missing = [i for i in args.silent + args.corrupt if i not in arm.ids]
        if missing:
            out.say(f"note: {', '.join(map(str, missing))} not on this bus (--ids); no fault for them")
        if args.silent or args.corrupt:
            if args.fault_after:
                timers.append(threading.Timer(args.fault_after, faults))
            else:
                faults()
        if args.close_after is not None:
            timers.append(threading.Timer(args.close_after, unplug))
        for timer in timers:
            timer.daemon = True
            timer.start()

        interactive = sys.stdin is not None and sys.stdin.isatty()
        while True:
            if interactive:
                print("fake-arm> ", end="", flush=True)
            line = sys.stdin.readline() if sys.stdin is not None else ""
            if not line:
                out.say("end of input: the emulator keeps running until Ctrl-C or SIGTERM")
                while True:
                    time.sleep(3600)
            if not _command(arm, line, out.say):
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
