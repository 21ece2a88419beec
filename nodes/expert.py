"""expert: the scripted expert of a task, a sender of `joint_cmd` like the prompt or the leader.

It reads only `joint_state`, `gripper_state` and `object_state`, from a body in lockstep
(so101/runtime/lockstep.py): once the three parts of a frame are in, it answers that frame
with six joint targets, tagged with it. A frame 0 is a new episode (a reset): a fresh plan
for the layout it shows, its noise drawn from the layout's seed. Its clock is the frame's
index over the frame rate, so the same layout gives the same episode however fast the
machine. What it plans is so101/tasks/expert.py.
Settings: so101.tasks.settings.ExpertSettings (SO101_TASK, SO101_EXPERT_NOISE, SO101_LOCKSTEP_FPS, SO101_LANG).
"""

from __future__ import annotations

import logging
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere: the so101 package sits beside nodes/
    sys.path.insert(0, str(ROOT))

import pyarrow as pa  # noqa: E402
from dora import Node  # noqa: E402

from so101.assets import ModelFilesError  # noqa: E402
from so101.bodies.node_loop import STREAM_KEY, cannot_start  # noqa: E402
from so101.runtime.lockstep import FrameParts, frame_tag  # noqa: E402
from so101.runtime.logs import send_diagnostics_to  # noqa: E402
from so101.runtime.node_events import inputs_until_stop  # noqa: E402
from so101.tasks import task_named  # noqa: E402
from so101.tasks.expert import Expert, Planner, planner_for  # noqa: E402
from so101.tasks.settings import ExpertSettings  # noqa: E402

NODE_ID = "expert"
logger = logging.getLogger("so101.expert")


def main() -> int:
    send_diagnostics_to("stdout")
    try:
        settings = ExpertSettings.from_environ(os.environ)
        planner: Planner = planner_for(task_named(settings.task))
    except (ValueError, ModelFilesError) as error:
        return cannot_start(error, NODE_ID)
    frames = FrameParts(("joint_state", "gripper_state", "object_state"))
    expert: Expert | None = None
    node = Node()
    with inputs_until_stop(node, close=planner.close) as inputs:
        for event in inputs:
            tag = frame_tag(event.get("metadata"))
            if tag is None:
                continue  # not a lockstep frame's
            frame = frames.add(event["id"], tag, event["value"].to_pylist())
            if frame is None:
                continue
            joints_deg = frame["joint_state"] + frame["gripper_state"]
            if expert is None or tag.frame == 0:
                expert = Expert(planner, noise=settings.noise, seed=tag.seed)
            targets_deg = expert.targets(tag.frame / settings.lockstep_fps, joints_deg, frame["object_state"])
            node.send_output("joint_cmd", pa.array(targets_deg, type=pa.float64()), {**tag.metadata(), STREAM_KEY: 1})
    return 0


if __name__ == "__main__":
    sys.exit(main())
