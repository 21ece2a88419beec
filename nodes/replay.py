"""replay: plays an episode of a LeRobot dataset onto whichever body runs the dataflow.

`so101 replay DIR --episode N` starts the body's dataflow with this node in the prompt's place
(a dynamic node, so its lines reach the terminal), then runs it. It waits for the body's first
state, moves the arm from where it stands to the episode's first action along a straight line
with no joint faster than 30°/s, waits for it to settle, then sends one `joint_cmd` (all six
joints) per frame at the dataset's rate. Its last line compares each frame's action with the
state the body reached by the next frame: `tracking error (deg): p50 A, p99 B, max C`; then the
body's joints against the recording's own states at the same instants: `versus the recording: ...`.
The joints are read in the dataset's units (so101.dataset.units). Settings:
so101.dataset.settings.ReplaySettings (SO101_REPLAY_DIR, SO101_REPLAY_EPISODE, SO101_REPLAY_UNITS,
SO101_REPLAY_CALIBRATION, SO101_LANG; SO101_DAEMON_PORT as the prompt's).
"""

from __future__ import annotations

import math
import os
import sys
import time
from pathlib import Path
from typing import Sequence

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
import pyarrow as pa  # noqa: E402

from so101.dataset.features import ACTION_KEY, STATE_KEY  # noqa: E402
from so101.dataset.layout import DatasetError  # noqa: E402
from so101.dataset.reader import Dataset  # noqa: E402
from so101.dataset.replay import (  # noqa: E402
    RAMP_SPEED_DEG_S, SETTLE_TIMEOUT_S, ramp_deg, send_time_s, settled, tracking_errors_deg, tracking_line,
    versus_recording_line,
)
from so101.dataset.settings import ReplaySettings  # noqa: E402
from so101.prompt.join import join_dataflow  # noqa: E402
from so101.prompt.settings import PromptSettings  # noqa: E402
from so101.prompt.terminal import dora_logs_aside  # noqa: E402
from so101.robot import NUM_ARM_JOINTS  # noqa: E402
from so101.runtime.dataflow import REPLAY_NODE_ID  # noqa: E402
from so101.runtime.logs import send_diagnostics_to  # noqa: E402

FIRST_STATE_WAIT_S = 10.0
_KEPT_TO_EXIT: list = []  # the joined node, as the prompt keeps it (nodes/keyboard_control.py says why)

TEXT = {
    "zh": {
        "episode": "第 {episode} 段({root}):{frames} 帧,{fps} 帧/秒({seconds:.1f} 秒),任务 '{task}'",
        "ramp": "以不超过 {speed:g}°/秒 移到第一帧({seconds:.1f} 秒)",
        "play": "回放中…",
        "no_state": "{seconds:g} 秒内没有收到 joint_state:身体节点在运行吗?",
        "stopped": "数据流已停止,回放中断",
    },
    "en": {
        "episode": "episode {episode} of {root}: {frames} frames at {fps} fps ({seconds:.1f} s), task '{task}'",
        "ramp": "moving to the first frame at no more than {speed:g}°/s ({seconds:.1f} s)",
        "play": "playing...",
        "no_state": "no joint_state within {seconds:g} s: is the body's node running?",
        "stopped": "the dataflow stopped: replay cut short",
    },
}


class Stopped(Exception):
    """STOP came: the dataflow is ending."""


class Body:
    """The body as the replay node sees it: the latest six angles, and joint_cmd out."""

    def __init__(self, node) -> None:
        self.node = node
        self.arm_deg: list[float] | None = None
        self.gripper_deg: float | None = None

    def state_deg(self) -> np.ndarray | None:
        if self.arm_deg is None or self.gripper_deg is None:
            return None
        return np.array(self.arm_deg + [self.gripper_deg])

    def reached_deg(self) -> np.ndarray:
        """The latest six angles, once the first state has come."""
        state = self.state_deg()
        if state is None:
            raise RuntimeError("no state yet")
        return state

    def wait_until(self, deadline: float) -> None:
        """Take the node's events until the monotonic `deadline`."""
        while True:
            remaining_s = deadline - time.monotonic()
            if remaining_s <= 0:
                return
            event = self.node.next(timeout=remaining_s)
            if event is None:
                continue
            if event["type"] == "STOP":
                raise Stopped
            if event["type"] == "INPUT":
                values = event["value"].to_pylist()
                if event["id"] == "joint_state" and len(values) == NUM_ARM_JOINTS:
                    self.arm_deg = values
                elif event["id"] == "gripper_state" and len(values) == 1:
                    self.gripper_deg = values[0]

    def send(self, angles_deg: Sequence[float]) -> None:
        self.node.send_output("joint_cmd", pa.array([float(angle) for angle in angles_deg], type=pa.float64()))


def play(body: Body, actions_deg: np.ndarray, fps: int, text: dict, states_deg: np.ndarray | None = None) -> list[str]:
    """The move to the first frame, then every frame at its time (a period after the last one when
    late); returns the tracking line, and with the recording's `states_deg` the line comparing them."""
    deadline = time.monotonic() + FIRST_STATE_WAIT_S
    while body.state_deg() is None:
        if time.monotonic() >= deadline:
            raise TimeoutError(text["no_state"].format(seconds=FIRST_STATE_WAIT_S))
        body.wait_until(min(deadline, time.monotonic() + 0.05))
    waypoints = ramp_deg(body.reached_deg(), actions_deg[0], fps)
    print(text["ramp"].format(speed=RAMP_SPEED_DEG_S, seconds=len(waypoints) / fps), flush=True)
    period_s = 1.0 / fps
    start, sent_s = time.monotonic(), -math.inf
    for index, waypoint in enumerate(waypoints):
        body.wait_until(send_time_s(start, index, period_s, sent_s))
        sent_s = time.monotonic()
        body.send(waypoint)
    settle_deadline = time.monotonic() + SETTLE_TIMEOUT_S
    while time.monotonic() < settle_deadline and not settled(body.reached_deg(), actions_deg[0]):
        body.wait_until(time.monotonic() + period_s)
    print(text["play"], flush=True)
    reached_deg = np.empty_like(actions_deg)
    start, sent_s = time.monotonic(), -math.inf
    for index, action in enumerate(actions_deg):
        body.wait_until(send_time_s(start, index, period_s, sent_s))
        if index:
            reached_deg[index - 1] = body.reached_deg()
        sent_s = time.monotonic()
        body.send(action)
    body.wait_until(sent_s + period_s)
    reached_deg[-1] = body.reached_deg()
    lines = [tracking_line(tracking_errors_deg(actions_deg, reached_deg))]
    if states_deg is not None and len(states_deg) > 1:
        lines.append(versus_recording_line(reached_deg, states_deg))
    return lines


def main() -> int:
    send_diagnostics_to("stderr")
    try:
        settings = ReplaySettings.from_environ(os.environ)
        prompt_settings = PromptSettings.from_environ(os.environ)
        dataset = Dataset.open(settings.root)
        units = dataset.joint_units(settings.units or None, settings.calibration, settings.episode)
        joints_deg = dataset.episode_joints_deg(settings.episode, units)
    except (ValueError, DatasetError) as error:
        print(f"{REPLAY_NODE_ID}: {error}", file=sys.stderr)
        return 2
    text = TEXT[settings.lang]
    actions_deg = joints_deg[ACTION_KEY]
    summary = dataset.episodes[[each.index for each in dataset.episodes].index(settings.episode)]
    print(text["episode"].format(episode=settings.episode, root=settings.root, frames=len(actions_deg),
                                 fps=dataset.fps, seconds=len(actions_deg) / dataset.fps,
                                 task=" | ".join(summary.tasks)), flush=True)
    # dora's own log lines (JSON) go to the prompt's log file, not between these lines.
    with dora_logs_aside(prompt_settings.log_file, restore=False):  # the node outlives the block, as the prompt's
        node = join_dataflow(REPLAY_NODE_ID, prompt_settings.daemon_port, settings.lang)
        if node is None:  # why is on stderr, in one line
            return 1
        _KEPT_TO_EXIT.append(node)
        try:
            print("\n".join(play(Body(node), actions_deg, dataset.fps, text, joints_deg.get(STATE_KEY))), flush=True)
        except Stopped:
            print(text["stopped"], file=sys.stderr, flush=True)
            return 1
        except TimeoutError as error:
            print(f"{REPLAY_NODE_ID}: {error}", file=sys.stderr, flush=True)
            return 1
        except KeyboardInterrupt:
            return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
