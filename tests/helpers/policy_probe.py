"""Run by the policy environment's Python (tests/test_policy.py): nodes/policy.py's main() on a
MockNode fed lockstep frames given as JSON on stdin, its outputs as JSON on stdout.

stdin: {"env": {...}, "frames": [[episode, frame, seed, joint_state, gripper_state, object_state], ...]}; a frame
may add its `image` and `wrist_image` (flat bytes), and its object_state may be null (a policy that sees).
stdout (last line): {"code": main()'s return, "joint_cmd": [[episode, frame, [six targets]], ...]}
"""

import json
import os
import sys
from pathlib import Path

import pyarrow as pa
from dora.testing import MockNode

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from nodes import policy  # noqa: E402


def main() -> None:
    asked = json.loads(sys.stdin.read())
    os.environ.update(asked["env"])
    events = []
    for episode, frame, seed, joint_state, gripper_state, object_state, *pictures in asked["frames"]:
        tags = {"episode": episode, "frame": frame, "seed": seed}
        for name, values in (("joint_state", joint_state), ("gripper_state", gripper_state),
                             ("object_state", object_state)):
            if values is not None:
                events.append({"type": "INPUT", "id": name, "value": pa.array(values, type=pa.float64()),
                               "metadata": dict(tags)})
        for name, values in zip(("image", "wrist_image"), pictures):
            events.append({"type": "INPUT", "id": name, "value": pa.array(values, type=pa.uint8()),
                           "metadata": dict(tags)})
    node = MockNode(events)
    sent = []
    keep = node.send_output

    def send_output(output_id, data, metadata=None):
        if output_id == "joint_cmd":
            sent.append([metadata["episode"], metadata["frame"], data.to_pylist()])
        keep(output_id, data, metadata)

    node.send_output = send_output
    policy.Node = lambda: node
    code = policy.main()
    print(json.dumps({"code": code, "joint_cmd": sent}))


if __name__ == "__main__":
    main()
