"""leader: an SO-101 leader arm as a dora node: the hand moves it, the body follows.

"Swap one driver node", the other way round: where dataflow.yml's body takes `joint_cmd` from
the keyboard prompt, dataflow_leader.yml's takes it from this node. Each `tick` (10 ms) it reads
the leader's six positions with one SYNC READ and sends them on `joint_cmd` as the follower's six
targets in degrees (the gripper's 0-100 mapped onto the follower's gripper), only when they
changed. The leader's torque stays off; torque found on is switched off at start.

The prompt's commands come in on `typed_cmd` and go out on `joint_cmd` as they are: a typed
command takes over until the leader moves again (so101/leader/command.py, Takeover). News for the
person (a takeover, the leader silent or back) goes out on `leader_status` for the prompt, and to
the log. A leader that stops answering or is unplugged sends nothing: the body holds where it is.
Settings: so101.leader.settings.LeaderSettings (SO101_LEADER_PORT, SO101_LEADER_CALIBRATION, ...).
"""

from __future__ import annotations

import logging
import os
import signal
import sys
from pathlib import Path
from types import FrameType

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import pyarrow as pa  # noqa: E402
from dora import Node  # noqa: E402

from so101.bodies.node_loop import announce  # noqa: E402
from so101.leader.arm import LeaderFailed, SO101Leader  # noqa: E402
from so101.leader.command import MOVED_DEG, Takeover  # noqa: E402
from so101.leader.settings import LeaderSettings  # noqa: E402
from so101.runtime.dataflow import timer_period_s  # noqa: E402
from so101.runtime.logs import send_diagnostics_to  # noqa: E402
from so101.runtime.node_events import STREAM_KEY, cannot_start, inputs_until_stop  # noqa: E402

NODE_ID = "leader"
# Marks a joint_cmd as a stream (one per tick): the body does not log each one.
STREAM_METADATA = {STREAM_KEY: NODE_ID}

TEXT = {
    "zh": {
        "ready": "[主臂] SO-101 主臂就绪,{port},{calibration}(扭矩关闭,每 {tick_ms:g} ms 读一次)",
        "typed": "键入的命令接管了控制;移动主臂(超过 {moved:g}°)即交还给主臂",
        "back": "主臂移动了:由主臂驱动",
    },
    "en": {
        "ready": "[leader] SO-101 leader ready, {port}, {calibration} (torque off, read every {tick_ms:g} ms)",
        "typed": "a typed command took over; move the leader (more than {moved:g}°) to drive with it again",
        "back": "the leader moved: it drives again",
    },
}
logger = logging.getLogger("so101.leader")


def _interrupt(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt  # SIGTERM ends the loop like Ctrl-C: the port is closed on the way out


def main() -> int:
    send_diagnostics_to("stdout")  # dora keeps a node's stdout in its log
    signal.signal(signal.SIGTERM, _interrupt)
    try:
        settings = LeaderSettings.from_environ(os.environ)
    except ValueError as error:
        return cannot_start(error, NODE_ID)
    node: Node | None = None
    text = TEXT[settings.lang]

    def report(line: str) -> None:
        """A line for the log and, where the dataflow has the prompt listening, for the person."""
        logger.warning(line)
        if node is not None and "leader_status" in (node.node_config() or {}).get("outputs", []):
            node.send_output("leader_status", pa.array([line]))

    try:
        leader = SO101Leader.from_settings(settings, report=report)
    except LeaderFailed as error:
        return cannot_start(error, NODE_ID)
    except KeyboardInterrupt:
        return 0
    node = Node()
    tick_s = timer_period_s(node.node_config()) or 0.01
    announce(text["ready"].format(port=leader.port, calibration=settings.calibration_file.name, tick_ms=tick_s * 1000))
    takeover = Takeover()
    last_sent_deg: tuple[float, ...] | None = None
    with inputs_until_stop(node, close=leader.close) as inputs:
        for event in inputs:
            if event["id"] == "tick":
                command_deg = leader.poll()
                if command_deg is None or command_deg == last_sent_deg:
                    continue  # silent, or unchanged: nothing stale is sent again
                was_typed = takeover.typed
                if not takeover.leader_drives(command_deg):
                    continue
                if was_typed:
                    report(text["back"])
                node.send_output("joint_cmd", pa.array(command_deg, type=pa.float64()), STREAM_METADATA)
                last_sent_deg = command_deg
            elif event["id"] == "typed_cmd":
                node.send_output("joint_cmd", event["value"])
                last_sent_deg = None  # the body's targets are the typed ones now
                if takeover.on_typed(leader.latest_deg):
                    report(text["typed"].format(moved=MOVED_DEG))
    return 0


if __name__ == "__main__":
    sys.exit(main())
