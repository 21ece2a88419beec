"""keyboard_control: the course's keyboard prompt (step D, exercise 1) as a dynamic dora node.

Start the dataflow first (`dora run dataflow.yml`), then in a second terminal:
    python nodes/keyboard_control.py
or both in one terminal: `so101 teleop`. Type `help` at the prompt for the commands.

Nodes that `dora run` starts get no usable terminal, so this node is `path: dynamic`
and joins the running dataflow by its id. A background thread keeps reading the
node's events (the latest `joint_state` and `gripper_state`, and STOP) while the
main thread waits for the keyboard: an input queue left unread would overflow, and
dora would print one JSON warning per dropped event into this terminal.

With a terminal, lines are read with line editing and history; with a pipe or a
file on stdin, each line is run in order, echoed with its reply, and the node exits
at the end of the input (for scripts and tests). dora's own log lines (JSON, written
by its Rust side straight to file descriptor 1) go to a log file for the whole session,
never between the person's commands.

Environment:
  SO101_LANG          zh (default, as the course) | en
  SO101_POSES_FILE    where saved poses are kept (default: saved_poses.json beside dataflow.yml)
  SO101_HISTORY_FILE  the prompt's line history (default: ~/.so101_history)
  SO101_PROMPT_LOG    where dora's log lines go (default: out/keyboard_control.log beside dataflow.yml)
  SO101_DAEMON_PORT   the local listen port of the dora daemon to join through (default: dora's own,
                      53291); on a cluster, that of this machine's daemon (`dora daemon --local-listen-port`)
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Callable, Sequence

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere: the so101 package sits beside nodes/
    sys.path.insert(0, str(ROOT))

from so101.prompt.commands import (  # noqa: E402
    LANGUAGES, Batch, Empty, GoPose, Help, Home, JogKeys, ListJoints, ListPoses, MoveTip, ParseError, Quit, SavePose,
    SetJoint, ShowState, Snapshot, Where, format_angle, format_angles, help_lines, joint_lines, parse_command, texts,
)
from so101.prompt.poses import Pose, PoseStore  # noqa: E402
from so101.robot import ACTUATED_JOINTS, NUM_ARM_JOINTS  # noqa: E402
from so101.prompt.terminal import dora_logs_to  # noqa: E402
from so101.runtime.versions import dora_version_mismatch, joined_daemon_version_problem  # noqa: E402

NODE_ID = "keyboard_control"
DEFAULT_POSES_FILE = ROOT / "saved_poses.json"
DEFAULT_HISTORY_FILE = Path("~/.so101_history")
DEFAULT_PROMPT_LOG = ROOT / "out" / "keyboard_control.log"
# How long `save` waits for a first joint_state (a piped script may start before one arrives).
FIRST_STATE_WAIT_S = 2.0
EVENT_WAIT_S = 0.2
# A body publishes joint_state every tick (4 or 20 ms): none for this long means it, its machine
# or the network between is gone (on a cluster nothing else tells the prompt).
STALE_STATE_S = 2.0
# Jog mode looks for a key this often, and sends a waiting command once a newer joint_state came.
JOG_POLL_S = 0.01

TEXT = {
    "zh": {
        "title": "  SO-101 键盘控制",
        "stopped": "  数据流已停止,退出",
        "join_failed": "无法作为 {node_id} 加入数据流(先在另一个终端运行 `dora run dataflow.yml`;集群上,本机的 "
        "`dora daemon` 须在运行): {error}",
        "join_no_place": "无法作为 {node_id} 加入数据流(此守护进程上没有含 {node_id} 的数据流:请先启动一个(`dora run "
        "dataflow.yml`,集群上用 `dora start`);若数据流已在运行,说明此机器的守护进程掉线后重启过,dora 1.1 不会把运行中的"
        "数据流交还给它:`dora restart so101` 重新启动数据流): {error}",
        "poses_file": "  姿态文件: {path}(已保存 {count} 个)",
    },
    "en": {
        "title": "  SO-101 keyboard control",
        "stopped": "  the dataflow stopped: quitting",
        "join_failed": "cannot join the dataflow as {node_id} (start it first in another terminal: "
        "`dora run dataflow.yml`; on a cluster, this machine's `dora daemon` must be running): {error}",
        "join_no_place": "cannot join the dataflow as {node_id} (this daemon has no dataflow with a {node_id} in it: "
        "start one (`dora run dataflow.yml`, or `dora start` on a cluster); if one runs, this machine's daemon was "
        "started again after it dropped out, and dora 1.1 does not hand a running dataflow back: `dora restart so101` "
        "starts it anew): {error}",
        "poses_file": "  poses file: {path} ({count} saved)",
    },
}


def say(line: str = "") -> None:
    print(line, flush=True)


class KeyboardControl:
    """What each command does: the joint_cmd it sends and the lines it replies.

    `send_joint_cmd` receives the angles in degrees ([idx, angle] or a batch);
    `on_event` takes the node's events (from any thread) to track the latest state.
    """

    def __init__(self, send_joint_cmd: Callable[[Sequence[float]], None], poses: PoseStore, lang: str = "zh"):
        self.send_joint_cmd = send_joint_cmd
        self.poses = poses
        self.lang = lang
        self.text = texts(lang)
        self._state_changed = threading.Condition()
        self.joint_state_deg: tuple[float, ...] | None = None
        self.gripper_deg: float | None = None
        self.states_seen = 0  # joint_state messages so far: one per tick of the body
        self._last_state_at: float | None = None  # time.monotonic() of the latest joint_state
        self.stopped = False
        self._kinematics = None
        # Runs key jogging and returns its closing lines; set by the prompt when it has a terminal.
        self.run_jog: Callable[[], list[str]] | None = None

    # -- events, from the pump thread ----------------------------------------------------
    def on_event(self, event: dict) -> None:
        if event["type"] == "STOP":
            with self._state_changed:
                self.stopped = True
                self._state_changed.notify_all()
        elif event["type"] == "INPUT" and event["id"] in ("joint_state", "gripper_state"):
            values = [float(angle) for angle in event["value"].to_pylist()]
            with self._state_changed:
                if event["id"] == "joint_state" and len(values) == NUM_ARM_JOINTS:
                    self.joint_state_deg = tuple(values)
                    self.states_seen += 1
                    self._last_state_at = time.monotonic()
                    self._state_changed.notify_all()
                elif event["id"] == "gripper_state" and len(values) == 1:
                    self.gripper_deg = values[0]

    def _wait_for_state(self, timeout_s: float) -> tuple[tuple[float, ...] | None, float | None]:
        with self._state_changed:
            self._state_changed.wait_for(lambda: self.joint_state_deg is not None or self.stopped, timeout_s)
            return self.joint_state_deg, self.gripper_deg

    def silent_for_s(self) -> float | None:
        """How long no joint_state has come, once they had been coming and stopped; else None."""
        with self._state_changed:
            if self._last_state_at is None or self.stopped:
                return None
            silent_s = time.monotonic() - self._last_state_at
        return silent_s if silent_s > STALE_STATE_S else None

    def latest_deg(self) -> tuple[float, ...] | None:
        """The six angles of the latest state (the gripper as 0 until its first state), or None."""
        with self._state_changed:
            if self.joint_state_deg is None:
                return None
            return self.joint_state_deg + (self.gripper_deg or 0.0,)

    def kinematics(self):
        """so101.kinematics.Kinematics, made on first use (PyBullet stays out of the prompt's
        start-up), or the exception that says why there is none."""
        if self._kinematics is None:
            from so101.assets import ModelFilesError
            from so101.kinematics import Kinematics
            from so101.prompt.terminal import stderr_to_log

            try:
                with stderr_to_log():
                    self._kinematics = Kinematics()
            except ModelFilesError as error:
                return error
        return self._kinematics

    # -- commands, from the main thread --------------------------------------------------
    def handle_line(self, line: str, state_wait_s: float = FIRST_STATE_WAIT_S) -> tuple[list[str], bool]:
        """Run one typed line: returns (reply lines, whether to quit)."""
        command = parse_command(line, self.lang)
        text = self.text
        if isinstance(command, ParseError):
            return [command.message], False
        if isinstance(command, Empty):
            return [], False
        if isinstance(command, Quit):
            return [text["bye"]], True
        if isinstance(command, Help):
            return help_lines(self.lang), False
        if isinstance(command, ListJoints):
            return joint_lines(self.lang), False
        silent_s = self.silent_for_s()
        if silent_s is not None:  # every other command moves the arm or reads its state: neither works now
            return [text["body_silent"].format(seconds=silent_s)], False
        if isinstance(command, Home):
            self.send_joint_cmd([0.0] * NUM_ARM_JOINTS)
            return [text["sent_home"]], False
        if isinstance(command, SetJoint):
            self.send_joint_cmd([float(command.index), command.angle_deg])
            name = ACTUATED_JOINTS[command.index].name
            return [text["sent_joint"].format(index=command.index, name=name, angle=format_angle(command.angle_deg))], False
        if isinstance(command, Batch):
            self.send_joint_cmd(list(command.angles_deg))
            return [self._batch_line(command.angles_deg)], False
        if isinstance(command, ShowState):
            return [self._state_line(state_wait_s)], False
        if isinstance(command, SavePose):
            return [self._save(command.name, state_wait_s)], False
        if isinstance(command, GoPose):
            pose = self.poses.get(command.name)
            if pose is None:
                known = ", ".join(self.poses.names()) or text["none"]
                return [text["unknown_pose"].format(name=command.name, known=known)], False
            self.send_joint_cmd(list(pose.joint_cmd_deg()))
            return [text["go"].format(name=command.name)], False
        if isinstance(command, ListPoses):
            return self._pose_lines(), False
        if isinstance(command, Snapshot):
            return [self._snapshot(command.path, state_wait_s)], False
        if isinstance(command, MoveTip):
            return [self._move_tip(command.target_mm, state_wait_s)], False
        if isinstance(command, Where):
            return [self._where(state_wait_s)], False
        if isinstance(command, JogKeys):
            return (self.run_jog() if self.run_jog else [text["jog_needs_terminal"]]), False
        raise AssertionError(f"unhandled command {command!r}")

    def _batch_line(self, angles_deg: Sequence[float]) -> str:
        arm = format_angles(angles_deg[:NUM_ARM_JOINTS])
        if len(angles_deg) == NUM_ARM_JOINTS:
            return self.text["sent_batch"].format(angles=arm)
        return self.text["sent_batch_gripper"].format(angles=arm, gripper=format_angle(angles_deg[NUM_ARM_JOINTS]))

    def _state_line(self, state_wait_s: float) -> str:
        joints_deg, gripper_deg = self._wait_for_state(state_wait_s)
        if joints_deg is None:
            return self.text["no_state_yet"]
        if gripper_deg is None:
            return self.text["state"].format(angles=format_angles(joints_deg))
        return self.text["state_gripper"].format(angles=format_angles(joints_deg), gripper=format_angle(round(gripper_deg, 2)))

    def _save(self, name: str, state_wait_s: float) -> str:
        joints_deg, gripper_deg = self._wait_for_state(state_wait_s)
        if joints_deg is None:
            return self.text["no_state"]
        # 0.01° is far below what the arm can hold; rounding keeps the file and the reply readable
        # (+ 0.0 turns a rounded -0.0 into 0.0).
        pose = Pose(
            tuple(round(angle, 2) + 0.0 for angle in joints_deg),
            None if gripper_deg is None else round(gripper_deg, 2) + 0.0,
        )
        problem = self.poses.save(name, pose)
        if problem:
            return self.text["saved_not_persisted"].format(name=name, error=problem)
        if pose.gripper_deg is None:
            return self.text["saved"].format(name=name, angles=format_angles(pose.joints_deg))
        return self.text["saved_gripper"].format(
            name=name, angles=format_angles(pose.joints_deg), gripper=format_angle(pose.gripper_deg)
        )

    def _snapshot(self, path: str, state_wait_s: float) -> str:
        joints_deg, gripper_deg = self._wait_for_state(state_wait_s)
        if joints_deg is None:
            return self.text["no_state_snapshot"]
        pose_deg = list(joints_deg) + ([] if gripper_deg is None else [gripper_deg])
        # `so101 snapshot` in its own process: PyBullet stays out of the prompt, and so does its banner.
        result = subprocess.run(
            [sys.executable, "-m", "so101.cli", "snapshot", "--out", path, "--pose", *(f"{angle:.2f}" for angle in pose_deg)],
            capture_output=True, text=True,
            env=dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))),
        )
        if result.returncode != 0:
            lines = (result.stderr or result.stdout).strip().splitlines()
            return self.text["snapshot_failed"].format(error=lines[-1] if lines else f"exit code {result.returncode}")
        return self.text["snapshot"].format(path=path)

    def _move_tip(self, target_mm: tuple[float, float, float], state_wait_s: float) -> str:
        kinematics = self.kinematics()
        if isinstance(kinematics, Exception):
            return self.text["no_kinematics"].format(error=kinematics)
        x, y, z = target_mm
        if z < 0:  # the base stands on the floor (or the table) at z = 0; IK knows nothing of it
            return self.text["below_floor"].format(x=x, y=y, z=z)
        joints_deg, _ = self._wait_for_state(state_wait_s)
        reach = kinematics.solve(target_mm, seed_deg=joints_deg)
        if not reach.reachable:
            nx, ny, nz = (round(value) + 0.0 for value in reach.tip_mm)
            return self.text["unreachable"].format(x=x, y=y, z=z, nx=nx, ny=ny, nz=nz, error=reach.error_mm)
        if joints_deg is not None and not kinematics.path_clear(joints_deg, reach.joints_deg):
            return self.text["through_floor"].format(x=x, y=y, z=z)
        self.send_joint_cmd(list(reach.joints_deg))  # the five arm joints; the gripper stays
        return self.text["sent_tip"].format(x=x, y=y, z=z, angles=format_angles(reach.joints_deg))

    def _where(self, state_wait_s: float) -> str:
        joints_deg, _ = self._wait_for_state(state_wait_s)
        if joints_deg is None:
            return self.text["no_state_where"]
        kinematics = self.kinematics()
        if isinstance(kinematics, Exception):
            return self.text["no_kinematics"].format(error=kinematics)
        x, y, z = (round(value, 1) + 0.0 for value in kinematics.tip_mm(joints_deg))  # + 0.0: no "-0.0"
        return self.text["where"].format(x=x, y=y, z=z)

    def _pose_lines(self) -> list[str]:
        if not self.poses.names():
            return [self.text["no_poses"]]
        lines = []
        for name in self.poses.names():
            pose = self.poses.get(name)
            if pose.gripper_deg is None:
                lines.append(self.text["pose_line"].format(name=name, angles=format_angles(pose.joints_deg)))
            else:
                lines.append(self.text["pose_line_gripper"].format(
                    name=name, angles=format_angles(pose.joints_deg), gripper=format_angle(pose.gripper_deg)))
        return lines


def _columns(fd: int) -> int:
    """The terminal's width (fd 1 is dora's log file here, so ask the keyboard's terminal)."""
    try:
        return os.get_terminal_size(fd).columns
    except OSError:
        return 80


def run_jog(control: KeyboardControl, fd: int) -> list[str]:
    """Key jogging at the terminal on `fd` (so101/prompt/jog.py says what each key does), until Esc or
    q; returns the closing lines. At most one joint_cmd per joint_state received, so holding a
    key never queues commands ahead of the arm. The terminal is restored however this ends."""
    from so101.prompt.jog import TEXT as JOG_TEXT, Jog, press, status_line
    from so101.prompt.terminal import single_keys

    text = control.text
    joints_deg, gripper_deg = control._wait_for_state(FIRST_STATE_WAIT_S)
    if joints_deg is None:
        return [text["jog_no_state"]]
    jog_text = JOG_TEXT[control.lang]
    for line in jog_text["map"]:
        say(line)
    jog = Jog(targets_deg=control.latest_deg())
    kinematics = None  # made when Cartesian mode is first asked for: it loads PyBullet
    waiting_deg, sent_at_state, shown = None, -1, ""
    try:
        with single_keys(fd) as keys:
            while True:
                key = keys.read(JOG_POLL_S)
                if key is not None:
                    if key == "tab" and kinematics is None:
                        kinematics = control.kinematics()
                    pressed = press(jog, key, control.latest_deg(), kinematics, control.lang)
                    jog = pressed.jog
                    if pressed.leave:
                        break
                    if pressed.show_map:
                        sys.stdout.write("\r\x1b[K" + "\n".join(jog_text["map"]) + "\n")
                        shown = ""
                    if pressed.send_deg is not None:
                        waiting_deg = pressed.send_deg
                if waiting_deg is not None and control.states_seen != sent_at_state:
                    control.send_joint_cmd(list(waiting_deg))
                    waiting_deg, sent_at_state = None, control.states_seen
                state_deg = control.latest_deg()
                tip_mm = kinematics.tip_mm(state_deg[:NUM_ARM_JOINTS]) if jog.cartesian and state_deg else None
                line = status_line(jog, state_deg, tip_mm, control.lang)[: _columns(fd) - 1]
                if line != shown:
                    sys.stdout.write("\r\x1b[K" + line)
                    sys.stdout.flush()
                    shown = line
    except EOFError:  # the terminal went away
        pass
    finally:
        sys.stdout.write("\n")
        sys.stdout.flush()
    return [text["jog_left"]]


def joint_cmd_sender(node) -> Callable[[Sequence[float]], None]:
    """Sends angles (degrees) on `joint_cmd` as a float64 Arrow array."""
    import pyarrow as pa

    def send(angles_deg: Sequence[float]) -> None:
        node.send_output("joint_cmd", pa.array([float(angle) for angle in angles_deg], type=pa.float64()))

    return send


class EventPump(threading.Thread):
    """Reads the node's events until STOP or `finish()`, so no input queue ever overflows."""

    def __init__(self, node, control: KeyboardControl, on_stop: Callable[[], None]):
        super().__init__(name="dora-events", daemon=True)
        self.node = node
        self.control = control
        self.on_stop = on_stop
        self._finish = threading.Event()
        # Set once the events buffered before this thread started have all been read.
        self.caught_up = threading.Event()

    def run(self) -> None:
        try:
            while not self._finish.is_set():
                if self.caught_up.is_set():
                    event = self.node.next(timeout=EVENT_WAIT_S)
                else:
                    event = self.node.try_recv()
                    if event is None:
                        self.caught_up.set()
                if event is None:
                    continue
                self.control.on_event(event)
                if event["type"] == "STOP":
                    if not self._finish.is_set():
                        self.on_stop()
                    return
        finally:
            self.caught_up.set()

    def finish(self) -> None:
        self._finish.set()
        self.join(timeout=2 * EVENT_WAIT_S + 1)


def _interrupt_main_thread() -> None:
    # The main thread sits in input() or readline(); only a signal wakes it (as KeyboardInterrupt).
    os.kill(os.getpid(), signal.SIGINT)


def _setup_line_editing(history_file: Path) -> Callable[[], None]:
    """Line editing and a persistent history where readline exists; returns the saver to call at exit."""
    try:
        import readline
    except ImportError:  # Windows without pyreadline: plain input() still works
        return lambda: None
    readline.set_history_length(1000)
    try:
        readline.read_history_file(history_file)
    except OSError:
        pass  # no history yet

    def save() -> None:
        try:
            readline.write_history_file(history_file)
        except OSError as error:
            say(f"  (history not saved to {history_file}: {error.strerror or error})")

    return save


def run_prompt(control: KeyboardControl, interactive: bool, history_file: Path) -> None:
    """The main loop: a person at a terminal, or a script on stdin."""
    lines_text = TEXT[control.lang]
    save_history = _setup_line_editing(history_file) if interactive else (lambda: None)
    try:
        while True:
            if interactive:
                try:
                    line = input("> ")
                except EOFError:  # Ctrl-D
                    say()
                    say(control.text["bye"])
                    return
            else:
                line = sys.stdin.readline()
                if not line:
                    return
                line = line.rstrip("\n")
                say(f"> {line}")
            replies, quit_now = control.handle_line(line)
            for reply in replies:
                say(reply)
            if quit_now:
                return
    except KeyboardInterrupt:  # Ctrl-C, or the dataflow stopped
        say()
        say(lines_text["stopped"] if control.stopped else control.text["bye"])
    finally:
        save_history()


def _arguments(argv: list[str] | None) -> None:
    parser = argparse.ArgumentParser(
        prog="keyboard_control.py",
        description="The SO-101 keyboard prompt: a dynamic dora node that joins a running `dora run dataflow.yml`. "
        "Type `help` at the prompt for the commands. A pipe or a file on stdin runs its lines in order and exits.",
        epilog="environment: SO101_LANG=zh|en (default zh); SO101_POSES_FILE (default "
        f"{DEFAULT_POSES_FILE}); SO101_HISTORY_FILE (default {DEFAULT_HISTORY_FILE}); SO101_PROMPT_LOG, where "
        f"dora's own log lines go (default {DEFAULT_PROMPT_LOG}); SO101_DAEMON_PORT, the daemon to join through "
        "(its --local-listen-port; default dora's)",
    )
    parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    _arguments(argv)
    lang = os.environ.get("SO101_LANG", "zh") or "zh"
    if lang not in LANGUAGES:
        print(f"keyboard_control: SO101_LANG={lang!r} is not one of: {', '.join(LANGUAGES)}", file=sys.stderr)
        return 2
    daemon_port = os.environ.get("SO101_DAEMON_PORT", "").strip()
    if daemon_port and not (daemon_port.isdigit() and 0 < int(daemon_port) < 65536):
        print(f"keyboard_control: SO101_DAEMON_PORT={daemon_port!r} is not a port number (1-65535)", file=sys.stderr)
        return 2
    poses_file = Path(os.environ.get("SO101_POSES_FILE") or DEFAULT_POSES_FILE).expanduser()
    history_file = Path(os.environ.get("SO101_HISTORY_FILE") or DEFAULT_HISTORY_FILE).expanduser()
    log_file = Path(os.environ.get("SO101_PROMPT_LOG") or DEFAULT_PROMPT_LOG).expanduser()
    with contextlib.ExitStack() as logs_aside:
        try:
            logs_aside.enter_context(dora_logs_to(log_file))
        except OSError as error:
            say(f"  (dora's log lines are dropped: cannot write {log_file}: {error.strerror or error})")
            logs_aside.enter_context(dora_logs_to(Path(os.devnull)))
        return _session(lang, poses_file, history_file, int(daemon_port) if daemon_port else None)


def _session(lang: str, poses_file: Path, history_file: Path, daemon_port: int | None = None) -> int:
    """Join the dataflow, then run the prompt until quit, end of input or STOP."""
    from dora import Node

    interactive = sys.stdin.isatty()
    poses = PoseStore(poses_file)
    control = KeyboardControl(lambda angles_deg: None, poses, lang)
    # Ctrl-C must raise KeyboardInterrupt even when started with SIGINT ignored: STOP relies on it too.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    daemon_problem = joined_daemon_version_problem(daemon_port)
    if daemon_problem:
        print(f"keyboard_control: {daemon_problem}", file=sys.stderr)
        return 1
    try:
        node = Node(NODE_ID, daemon_port=daemon_port) if daemon_port else Node(NODE_ID)
    except Exception as error:  # noqa: BLE001 - dora raises a bare RuntimeError with a multi-line chain
        reason = " ".join(str(error).split("Location:")[0].split())  # drop the Rust backtrace
        # dora's answer when no dataflow of this daemon has this node
        text = TEXT[lang]["join_no_place" if "no node with ID" in reason else "join_failed"]
        print(text.format(node_id=NODE_ID, error=reason), file=sys.stderr)
        mismatch = dora_version_mismatch()  # the likeliest cause when the dataflow does run
        if mismatch:
            print(f"keyboard_control: {mismatch}", file=sys.stderr)
        return 1
    control.send_joint_cmd = joint_cmd_sender(node)
    if interactive:
        control.run_jog = lambda: run_jog(control, sys.stdin.fileno())
    pump = EventPump(node, control, on_stop=_interrupt_main_thread)
    pump.start()
    try:
        # The input queues filled while joining: read them before the first command.
        pump.caught_up.wait(timeout=5)
    except KeyboardInterrupt:  # Ctrl-C, or STOP, while joining
        pump.finish()
        return 0

    if poses.load_notice:
        say(f"  {poses.load_notice}")
    if interactive:
        say("=" * 50)
        say(TEXT[lang]["title"])
        say("=" * 50)
        for line in help_lines(lang):
            say(line)
        say(TEXT[lang]["poses_file"].format(path=poses_file, count=len(poses.names())))
        say("=" * 50)

    try:
        run_prompt(control, interactive, history_file)
    finally:
        try:
            pump.finish()
        except KeyboardInterrupt:  # STOP arrived while quitting anyway
            pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
