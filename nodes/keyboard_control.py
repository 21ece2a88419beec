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
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path
from typing import Callable, Sequence

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere: the so101 package sits beside nodes/
    sys.path.insert(0, str(ROOT))

from so101.commands import (  # noqa: E402
    LANGUAGES, Batch, Empty, GoPose, Help, Home, ListJoints, ListPoses, ParseError, Quit, SavePose, SetJoint, ShowState,
    Snapshot, format_angle, format_angles, help_lines, joint_lines, parse_command, texts,
)
from so101.poses import Pose, PoseStore  # noqa: E402
from so101.robot import ACTUATED_JOINTS, NUM_ARM_JOINTS  # noqa: E402
from so101.terminal import dora_logs_to  # noqa: E402
from so101.versions import dora_version_mismatch  # noqa: E402

NODE_ID = "keyboard_control"
DEFAULT_POSES_FILE = ROOT / "saved_poses.json"
DEFAULT_HISTORY_FILE = Path("~/.so101_history")
DEFAULT_PROMPT_LOG = ROOT / "out" / "keyboard_control.log"
# How long `save` waits for a first joint_state (a piped script may start before one arrives).
FIRST_STATE_WAIT_S = 2.0
EVENT_WAIT_S = 0.2

TEXT = {
    "zh": {
        "title": "  SO-101 键盘控制",
        "stopped": "  数据流已停止,退出",
        "join_failed": "无法作为 {node_id} 加入数据流(先在另一个终端运行 `dora run dataflow.yml`): {error}",
        "poses_file": "  姿态文件: {path}(已保存 {count} 个)",
    },
    "en": {
        "title": "  SO-101 keyboard control",
        "stopped": "  the dataflow stopped: quitting",
        "join_failed": "cannot join the dataflow as {node_id} (start it first in another terminal: "
        "`dora run dataflow.yml`): {error}",
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
        self.stopped = False

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
                    self._state_changed.notify_all()
                elif event["id"] == "gripper_state" and len(values) == 1:
                    self.gripper_deg = values[0]

    def _wait_for_state(self, timeout_s: float) -> tuple[tuple[float, ...] | None, float | None]:
        with self._state_changed:
            self._state_changed.wait_for(lambda: self.joint_state_deg is not None or self.stopped, timeout_s)
            return self.joint_state_deg, self.gripper_deg

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
        f"dora's own log lines go (default {DEFAULT_PROMPT_LOG})",
    )
    parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    _arguments(argv)
    lang = os.environ.get("SO101_LANG", "zh") or "zh"
    if lang not in LANGUAGES:
        print(f"keyboard_control: SO101_LANG={lang!r} is not one of: {', '.join(LANGUAGES)}", file=sys.stderr)
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
        return _session(lang, poses_file, history_file)


def _session(lang: str, poses_file: Path, history_file: Path) -> int:
    """Join the dataflow, then run the prompt until quit, end of input or STOP."""
    from dora import Node

    interactive = sys.stdin.isatty()
    poses = PoseStore(poses_file)
    control = KeyboardControl(lambda angles_deg: None, poses, lang)
    # Ctrl-C must raise KeyboardInterrupt even when started with SIGINT ignored: STOP relies on it too.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        node = Node(NODE_ID)
    except Exception as error:  # noqa: BLE001 - dora raises a bare RuntimeError with a multi-line chain
        reason = " ".join(str(error).split("Location:")[0].split())  # drop the Rust backtrace
        print(TEXT[lang]["join_failed"].format(node_id=NODE_ID, error=reason), file=sys.stderr)
        mismatch = dora_version_mismatch()  # the likeliest cause when the dataflow does run
        if mismatch:
            print(f"keyboard_control: {mismatch}", file=sys.stderr)
        return 1
    control.send_joint_cmd = joint_cmd_sender(node)
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
