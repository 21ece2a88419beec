"""What each command of the keyboard prompt does: the joint_cmd it sends and the lines it replies.

`KeyboardControl` needs neither dora nor a terminal: the node hands it a function that sends
`joint_cmd` and the node's events, so tests drive it with a MockNode. Kinematics (PyBullet)
and key jogging load on first use only, to keep the prompt's start-up quick.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import threading
import time
from typing import Callable, Sequence

from so101.prompt.commands import (
    Batch, Empty, Episodes, GoPose, Help, Home, JogKeys, ListJoints, ListPoses, MoveTip, ParseError, Quit, ResetTask, RunExpert, RunPolicy,
    SavePose, SetJoint, ShowState, ShowTask, Snapshot, Where, format_angle, format_angles, help_lines, joint_lines, parse_command, texts,
)
from so101.prompt.landing import SettleWatch, worth_saying
from so101.prompt.poses import Pose, PoseStore
from so101.prompt.recorder_link import REPLY_WAIT_S, RecorderLink
from so101.prompt import task_link
from so101.prompt.task_link import TaskLink, TaskStatus
from so101.robot import ACTUATED_JOINTS, NUM_ARM_JOINTS
from so101.runtime.dataflow import ROOT
from so101.tasks.news import LANDED

# How long `save` (and `task`) wait for a first joint_state (task_status) (a piped script may start
# before one arrives; the body sends task_status once a second).
FIRST_STATE_WAIT_S = 2.0
# A body publishes joint_state every tick (4 or 20 ms): none for this long means it, its machine
# or the network between is gone (on a cluster nothing else tells the prompt).
STALE_STATE_S = 2.0


class KeyboardControl:
    """What each command does: the joint_cmd it sends and the lines it replies.

    `send_joint_cmd` receives the angles in degrees ([idx, angle] or a batch);
    `on_event` takes the node's events (from any thread) to track the latest state;
    `keys_fd` is the terminal `jog` reads keys from (None: stdin is no terminal);
    `recorder` the line to the recorder node (None: the dataflow records nothing).
    """

    def __init__(self, send_joint_cmd: Callable[[Sequence[float]], None], poses: PoseStore, lang: str = "zh",
                 keys_fd: int | None = None, recorder: RecorderLink | None = None):
        self._send_joint_cmd = send_joint_cmd
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
        # After `xyz`: (the watch over the states, the target in mm), until the arm stopped or another command.
        self._landing: tuple[SettleWatch, tuple[float, float, float]] | None = None
        self.keys_fd = keys_fd
        self.recorder = recorder
        self.jogging = False  # `jog` has the terminal
        self.news_shown = 0  # lines of news printed while jogging (jog draws its status line again)
        # Prints a line of news at once (the leader's, on `leader_status`); None: nowhere to show it.
        self.show_news: Callable[[str], None] | None = None
        # News that came while a typed line was being answered: shown once the prompt is back (hold_news).
        self._held_news: list[str] | None = None
        self._news_lock = threading.Lock()
        # The line to a body running a task (`so101 teleop --task`); None: the dataflow runs none.
        self.task: TaskLink | None = None
        # Sends a word ("run", "stop") to the task's expert node, where the dataflow has one.
        self.tell_expert: Callable[[str], None] | None = None
        # Sends a word ("on", "off") to the policy node, where the dataflow has one.
        self.tell_policy: Callable[[str], None] | None = None

    def hold_news(self) -> None:
        """From a typed line until `release_news`, news waits: `policy on` prints its own reply before the
        policy's answer to it, however fast that came, and news never lands between the prompt's lines."""
        with self._news_lock:
            if self._held_news is None:
                self._held_news = []

    def release_news(self) -> None:
        """Shows the news held since `hold_news`, and news from now on at once. At a terminal, readline
        calls it once the next prompt is drawn (nodes/keyboard_control.py), so news redraws that prompt."""
        with self._news_lock:
            held, self._held_news = self._held_news or [], None
        for line in held:
            self.news(line)

    def news(self, line: str) -> None:
        """Shows a line of news, or holds it while a typed line is answered (jog shows it at once)."""
        with self._news_lock:
            if self._held_news is not None and not self.jogging:
                self._held_news.append(line)
                return
        if self.show_news is not None:
            self.show_news(line)

    # -- events, from the pump thread ----------------------------------------------------
    def on_event(self, event: dict) -> None:
        if event["type"] == "STOP":
            with self._state_changed:
                self.stopped = True
                self._state_changed.notify_all()
        elif event["type"] == "INPUT" and event["id"] == "record_status" and self.recorder is not None:
            status = event["value"].to_pylist()
            reply_to = str((event.get("metadata") or {}).get("reply_to", ""))
            self.recorder.on_status(str(status[0]) if status else "", reply_to)
        elif event["type"] == "INPUT" and event["id"] == "task_status" and self.task is not None:
            values = event["value"].to_pylist()
            if len(values) == 1:
                self.task.on_status(bool(values[0]), dict(event.get("metadata") or {}))
        elif event["type"] == "INPUT" and event["id"] == "object_state" and self.task is not None:
            self.task.on_objects(event["value"])  # 250 a second: read when `task` asks, not here
        elif event["type"] == "INPUT" and event["id"] in ("leader_status", "expert_status", "policy_status") and self.show_news is not None:
            for line in event["value"].to_pylist():
                self.news(f"  {line}")
        elif event["type"] == "INPUT" and event["id"] in ("joint_state", "gripper_state"):
            values = [float(angle) for angle in event["value"].to_pylist()]
            landing, landed_deg = None, None
            with self._state_changed:
                if event["id"] == "joint_state" and len(values) == NUM_ARM_JOINTS:
                    self.joint_state_deg = tuple(values)
                    self.states_seen += 1
                    self._last_state_at = time.monotonic()
                    self._state_changed.notify_all()
                    landing = self._landing
                    if landing is not None:
                        landed_deg = landing[0].add(self._last_state_at, values)
                        if landing[0].done:
                            self._landing = None
                elif event["id"] == "gripper_state" and len(values) == 1:
                    self.gripper_deg = values[0]
            if landing is not None and landed_deg is not None:  # FK and a printed line: outside the lock
                self._say_landing(landing[1], landed_deg)

    def wait_for_state(self, timeout_s: float) -> tuple[tuple[float, ...] | None, float | None]:
        """The latest arm angles and gripper angle, once a first joint_state (or STOP) came or
        `timeout_s` passed: (None, None) if none came."""
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

    def send_joint_cmd(self, angles_deg: Sequence[float]) -> None:
        """Send joint_cmd; the arm's next move is this one, not the last `xyz`'s."""
        self._landing = None
        self._send_joint_cmd(angles_deg)

    def _say_landing(self, target_mm: tuple[float, float, float], landed_deg: Sequence[float]) -> None:
        """Where the tip came to rest after `xyz`, if that is off the target (the pump thread)."""
        kinematics = self.kinematics()
        if isinstance(kinematics, Exception) or self.show_news is None:
            return
        landed_mm = kinematics.tip_mm(landed_deg)
        if worth_saying(target_mm, landed_mm):
            x, y, z = (round(value, 1) + 0.0 for value in landed_mm)
            tx, ty, tz = target_mm
            self.news(self.text["landed"].format(x=x, y=y, z=z, tx=tx, ty=ty, tz=tz, off=math.dist(target_mm, landed_mm)))

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
    def start_lines(self, interactive: bool) -> list[str]:
        """The lines before the first command: a bad poses file's notice, and at a terminal the
        title, the commands and where poses are kept."""
        lines = [f"  {self.poses.load_notice}"] if self.poses.load_notice else []
        if interactive:
            rule = "=" * 50
            lines += [rule, self.text["title"], rule, *help_lines(self.lang),
                      self.text["poses_file"].format(path=self.poses.path, count=len(self.poses.names())), rule]
        return lines

    def handle_line(self, line: str, state_wait_s: float = FIRST_STATE_WAIT_S) -> tuple[list[str], bool]:
        """Run one typed line: returns (reply lines, whether to quit)."""
        self._landing = None  # any other line ends the watch after `xyz`: its news would cut into the replies
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
        if isinstance(command, Episodes):  # the recorder answers for itself, the body alive or not
            return self.ask_recorder(command.command, command.task), False
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
        if isinstance(command, ResetTask):
            return [self._reset_task(command.seed)], False
        if isinstance(command, ShowTask):
            return self._task_lines(state_wait_s), False
        if isinstance(command, RunExpert):
            if self.tell_expert is None:
                return [text["task_off"]], False
            self._landing = None
            self.tell_expert("run")
            return [text["expert_started"]], False
        if isinstance(command, RunPolicy):
            if self.tell_policy is None:
                return [text["policy_none"]], False
            self._landing = None
            self.tell_policy(command.word)
            return [text["policy_asked"].format(word=command.word)], False
        if isinstance(command, JogKeys):
            if self.keys_fd is None:
                return [text["jog_needs_terminal"]], False
            from so101.prompt.jog_loop import run_jog

            self.jogging = True
            try:
                return run_jog(self, self.keys_fd, FIRST_STATE_WAIT_S), False
            finally:
                self.jogging = False
        raise AssertionError(f"unhandled command {command!r}")

    def ask_recorder(self, command: str, task: str = "") -> list[str]:
        """The recorder's answer to `record`, `stop`, `discard`, `episodes` or `toggle` (jog's key)."""
        if self.recorder is None:
            return [self.text["record_off"]]
        answer = self.recorder.ask(command, task)
        if answer is None:
            return [self.text["recorder_silent"].format(seconds=REPLY_WAIT_S)]
        return [f"  {line}" for line in answer]

    def task_news(self, status: TaskStatus, news: str) -> None:
        """The cube came to rest in the box, or was taken from there: so101.tasks.news' LANDED or LEFT
        (the task link's on_news, on the pump thread)."""
        if self.show_news is not None:
            self.news(self.text[news].format(task=status.task, seed=status.seed))
        if news == LANDED and self.tell_policy is not None:
            # The episode is over, as so101 eval ends it: the demonstrations show nothing after it, and a
            # policy left driving nudges the cube in the box (it says `stopped` if it was driving).
            self.tell_policy("off")

    def _layout_text(self, task_name: str, seed: int) -> str:
        from so101.tasks import task_named

        layout = task_named(task_name).layout(seed)
        return self.text["layout"].format(
            x=layout.cube_xyz_m[0] * 1000, y=layout.cube_xyz_m[1] * 1000, yaw=math.degrees(layout.cube_yaw_rad) + 0.0,
            box_x=layout.box_xyz_m[0] * 1000, box_y=layout.box_xyz_m[1] * 1000)

    def _reset_task(self, seed: int | None) -> str:
        if self.task is None:
            return self.text["task_off"]
        self._landing = None
        if self.tell_expert is not None:
            self.tell_expert("stop")  # its plan was for the scene that is going
        if self.tell_policy is not None:
            self.tell_policy("off")  # the scene it was acting in is going
        status = self.task.reset(seed)
        if status is None:
            return self.text["task_silent"].format(seconds=task_link.REPLY_WAIT_S)
        return self.text["laid_out"].format(seed=status.seed, layout=self._layout_text(status.task, status.seed))

    def _task_lines(self, state_wait_s: float) -> list[str]:
        if self.task is None:
            return [self.text["task_off"]]
        # A prompt that just joined waits for the body's next task_status (one a second).
        status, objects = self.task.wait_for_status(state_wait_s), self.task.object_state
        if status is None or objects is None:
            return [self.text["no_task_state"]]
        x, y, z = (value * 1000 + 0.0 for value in objects[0:3])
        verdict = self.text["in_box" if status.success else "not_in_box"]
        return [self.text["task_line"].format(task=status.task, seed=status.seed,
                                              layout=self._layout_text(status.task, status.seed)),
                self.text["cube_now"].format(x=x, y=y, z=z, verdict=verdict)]

    def _batch_line(self, angles_deg: Sequence[float]) -> str:
        arm = format_angles(angles_deg[:NUM_ARM_JOINTS])
        if len(angles_deg) == NUM_ARM_JOINTS:
            return self.text["sent_batch"].format(angles=arm)
        return self.text["sent_batch_gripper"].format(angles=arm, gripper=format_angle(angles_deg[NUM_ARM_JOINTS]))

    def _state_line(self, state_wait_s: float) -> str:
        joints_deg, gripper_deg = self.wait_for_state(state_wait_s)
        if joints_deg is None:
            return self.text["no_state_yet"]
        if gripper_deg is None:
            return self.text["state"].format(angles=format_angles(joints_deg))
        return self.text["state_gripper"].format(angles=format_angles(joints_deg), gripper=format_angle(round(gripper_deg, 2)))

    def _save(self, name: str, state_wait_s: float) -> str:
        joints_deg, gripper_deg = self.wait_for_state(state_wait_s)
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
        joints_deg, gripper_deg = self.wait_for_state(state_wait_s)
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
        joints_deg, _ = self.wait_for_state(state_wait_s)
        reach = kinematics.solve(target_mm, seed_deg=joints_deg)
        if not reach.reachable:
            nx, ny, nz = (round(value) + 0.0 for value in reach.tip_mm)
            return self.text["unreachable"].format(x=x, y=y, z=z, nx=nx, ny=ny, nz=nz, error=reach.error_mm)
        if joints_deg is not None and not kinematics.path_clear(joints_deg, reach.joints_deg):
            return self.text["through_floor"].format(x=x, y=y, z=z)
        self.send_joint_cmd(list(reach.joints_deg))  # the five arm joints; the gripper stays
        self._landing = (SettleWatch(time.monotonic()), target_mm)
        return self.text["sent_tip"].format(x=x, y=y, z=z, angles=format_angles(reach.joints_deg))

    def _where(self, state_wait_s: float) -> str:
        joints_deg, _ = self.wait_for_state(state_wait_s)
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
            pose = self.poses.poses[name]
            if pose.gripper_deg is None:
                lines.append(self.text["pose_line"].format(name=name, angles=format_angles(pose.joints_deg)))
            else:
                lines.append(self.text["pose_line_gripper"].format(
                    name=name, angles=format_angles(pose.joints_deg), gripper=format_angle(pose.gripper_deg)))
        return lines
