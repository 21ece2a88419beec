"""Benchmark node: the lockstep loop's messages with no work between them (`so101 bench --demos`).

As ECHO_ROLE=body it publishes a frame's four outputs (a body's joint_state, gripper_state,
object_state, task_status: small float arrays, tagged as lockstep tags them), then waits for the
driver's joint_cmd for that frame, ECHO_FRAMES times; it writes the mean milliseconds a frame
took, after ECHO_WARMUP frames, to ECHO_OUT. As ECHO_ROLE=driver it answers each frame once its
three parts are in; as ECHO_ROLE=watcher it takes every message, as the episodes' runner does.
"""

import os
import time

import numpy as np
import pyarrow as pa
from dora import Node

OUTPUTS = (("joint_state", 5), ("gripper_state", 1), ("object_state", 10), ("task_status", 1))


def main() -> None:
    role = os.environ["ECHO_ROLE"]
    node = Node()
    if role == "body":
        frames, warmup = int(os.environ["ECHO_FRAMES"]), int(os.environ.get("ECHO_WARMUP", "100"))
        started = 0.0
        for frame in range(frames + warmup):
            if frame == warmup:
                started = time.perf_counter()
            tags = {"episode": 1, "frame": frame, "seed": 0}
            for output, size in OUTPUTS:
                node.send_output(output, pa.array(np.zeros(size)), tags)
            while True:
                event = node.next()
                if event is None or event["type"] == "STOP":
                    return
                if event["type"] == "INPUT" and event["metadata"].get("frame") == frame:
                    break
        with open(os.environ["ECHO_OUT"], "w", encoding="utf-8") as out:
            out.write(f"{1000 * (time.perf_counter() - started) / frames:.3f}\n")
        return
    parts: dict[int, int] = {}
    for event in node:
        if event["type"] == "STOP":
            return
        if event["type"] != "INPUT" or role != "driver":
            continue
        frame = event["metadata"]["frame"]
        parts[frame] = parts.get(frame, 0) + 1
        if parts[frame] == 3:
            del parts[frame]
            node.send_output("joint_cmd", pa.array(np.zeros(6)), event["metadata"])


if __name__ == "__main__":
    main()
