"""perception: the eyes, taught by the simulator, in front of a state policy.

From the front camera's picture (`image`: the simulated camera's, or a real one's behind `--camera`)
and the arm's joints (`joint_state`), it sends `object_state`, the task's ten numbers as a simulation
publishes them: the cube's centre and yaw as the eyes see it (so101.perception.estimate: a pixel, a
height, and the camera's geometry checked against the box and the gripper's tip), the box where the
task stands it. The policy behind it reads this `object_state`, never the simulator's. While the cube's
map is unsure (the arm hides it), the cube stays where it was last seen: within an episode (lockstep), or
at the prompt from one `policy on` (`policy_cmd`) or layout (`task_status`'s seed) to the next. In lockstep (`so101 eval`) it
answers each frame once its picture and joints are in, tagged with it; at the prompt it sends one for
each picture, with the newest joints. Runs under the policy environment's Python (PyTorch).
Settings: so101.perception.settings.PerceptionSettings.
"""

from __future__ import annotations

import logging
import os
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere: the so101 package sits beside nodes/
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
import pyarrow as pa  # noqa: E402
from dora import Node  # noqa: E402

from so101.perception.eyes import Eyes  # noqa: E402
from so101.perception.settings import PerceptionSettings  # noqa: E402
from so101.runtime.lockstep import FrameParts, frame_tag  # noqa: E402
from so101.runtime.logs import send_diagnostics_to  # noqa: E402
from so101.runtime.node_events import cannot_start, inputs_until_stop  # noqa: E402
from so101.tasks import task_named  # noqa: E402

NODE_ID = "perception"
logger = logging.getLogger("so101.perception")
# so101 teleop waits for this line (so101.runtime.dataflow.PERCEPTION_READY_MARKS), in either language.
TEXT = {"en": "[perception] eyes loaded from {folder}: they see {width}x{height} pictures and send object_state",
        "zh": "[感知] 眼睛已加载({folder}):看 {width}x{height} 的画面,发出 object_state"}


def main() -> int:
    send_diagnostics_to("stdout")
    try:
        settings = PerceptionSettings.from_environ(os.environ)
        eyes = Eyes(settings.eyes_dir, task_named(settings.task), settings.threads, settings.camera_poses.get("front"))
    except (ValueError, OSError) as error:
        return cannot_start(error, NODE_ID)
    width, height = eyes.facts.size
    logger.warning(TEXT[settings.lang].format(folder=settings.eyes_dir, width=width, height=height))
    frames = FrameParts(("image", "joint_state"))
    episode: int | None = None
    joints: Any = None
    layout: object = None  # at the prompt, with a task: the seed of the layout laid out, from task_status
    node = Node()

    def send(picture: Any, arm_deg: Any, metadata: dict[str, Any]) -> None:
        state, _ = eyes.see(np.asarray(picture, dtype=np.uint8).reshape(height, width, 3), arm_deg)
        node.send_output("object_state", pa.array(state, type=pa.float64()), metadata)

    with inputs_until_stop(node, close=eyes.close) as inputs:
        for event in inputs:
            input_id, value = event["id"], event["value"].to_numpy(zero_copy_only=False)
            tag = frame_tag(event.get("metadata"))
            if tag is not None:  # lockstep: the frame's picture and joints, then its object_state
                frame = frames.add(input_id, tag, value)
                if frame is None:
                    continue
                if tag.frame == 0 or tag.episode != episode:
                    eyes.reset()
                episode = tag.episode
                send(frame["image"], frame["joint_state"], tag.metadata())
            elif input_id == "policy_cmd" and list(value[:1]) == ["on"]:
                eyes.reset()  # a new drive: the cube may have moved since the last one
            elif input_id == "task_status":
                seed = (event.get("metadata") or {}).get("seed")
                if seed != layout:
                    eyes.reset()  # a new layout (`reset` at the prompt): the old cube's place no longer holds
                layout = seed
            elif input_id == "joint_state":
                joints = value
            elif input_id == "image" and joints is not None:
                send(value, joints, {})
    return 0


if __name__ == "__main__":
    sys.exit(main())
