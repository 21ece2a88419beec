"""Benchmark node in the place of keyboard_control: sends joint_cmd probes, records joint_state.

Every $PROBE_PERIOD_S seconds (0 = never) it moves joint 0 or joint 4 (in turn) by
±$PROBE_STEP_DEG around 0, at a random phase of the tick ($PROBE_PHASE_S, default 4 ms)
so the wait for the next tick is sampled fairly. It records when each joint_state arrived
(time.monotonic_ns, the clock `so101 bench` and the simulation node's tick log use) with the
angles of joints 0 and 4 and when it was sent (dora's timestamp, on the same clock), and writes
everything to $PROBE_LOG (JSON) at STOP.
With $PROBE_COUNT_ONLY=1 it only counts states and keeps the first and last arrival:
the fast mode publishes far too many to keep. With $PROBE_RECORD_TASK set (and the recorder in
the dataflow) it starts an episode of that task at the first joint_state, as `record TASK`
would; the recorder saves it at STOP.
"""

import json
import os
import random
import time

import pyarrow as pa
from dora import Node

PROBED_JOINTS = (0, 4)
# A second in: the camera node has drawn its first picture by then (MuJoCo's renderer takes longest to start).
RECORD_AT_STATE = 250


def main() -> None:
    log_path = os.environ["PROBE_LOG"]
    period_ns = int(float(os.environ.get("PROBE_PERIOD_S", "0")) * 1e9)
    step_deg = float(os.environ.get("PROBE_STEP_DEG", "2"))
    count_only = os.environ.get("PROBE_COUNT_ONLY", "0") == "1"
    phase_ns = int(float(os.environ.get("PROBE_PHASE_S", "0.004")) * 1e9)
    record_task = os.environ.get("PROBE_RECORD_TASK", "")
    states = []  # [arrival ns, angle of joint 0, angle of joint 4, sent ns]
    commands = []  # [send ns, joint, target deg]
    state_count, first_ns, last_ns = 0, None, None
    node = Node()
    next_send_ns = None
    sent = 0
    while True:
        timeout_s = None if next_send_ns is None else max(0.0, (next_send_ns - time.monotonic_ns()) / 1e9)
        event = node.next(timeout=timeout_s)
        now_ns = time.monotonic_ns()
        if event is not None:
            if event["type"] == "STOP":
                break
            if event["type"] == "INPUT" and event["id"] == "joint_state":
                state_count += 1
                if first_ns is None:
                    first_ns = now_ns
                    print("bench: first joint_state", flush=True)  # so101 bench waits for this line
                if record_task and state_count == RECORD_AT_STATE:  # the recorder has had states too by now
                    node.send_output("record_cmd", pa.array([json.dumps({"command": "record", "task": record_task})]),
                                     {"request": "bench"})
                last_ns = now_ns
                if not count_only:
                    angles = event["value"].to_pylist()
                    # dora stamps each message with the sender's wall clock: moved onto the monotonic one.
                    sent_ago_ns = time.time_ns() - int(event["metadata"]["timestamp"].timestamp() * 1e9)
                    states.append([now_ns, angles[0], angles[4], now_ns - sent_ago_ns])
                    if next_send_ns is None and period_ns:
                        next_send_ns = now_ns + period_ns
        elif next_send_ns is None:
            break  # every sender is gone
        if next_send_ns is not None and now_ns >= next_send_ns:
            joint = PROBED_JOINTS[sent % len(PROBED_JOINTS)]
            # +step, +step, -step, -step, ...: each joint alternates direction.
            target_deg = step_deg if (sent // len(PROBED_JOINTS)) % 2 == 0 else -step_deg
            send_ns = time.monotonic_ns()
            node.send_output("joint_cmd", pa.array([float(joint), target_deg], type=pa.float64()))
            commands.append([send_ns, joint, target_deg])
            sent += 1
            next_send_ns = send_ns + period_ns + random.randrange(phase_ns)
    record = {"state_count": state_count, "first_state_ns": first_ns, "last_state_ns": last_ns,
              "states": states, "commands": commands, "probed_joints": list(PROBED_JOINTS)}
    with open(log_path + ".tmp", "w") as handle:
        json.dump(record, handle)
    os.replace(log_path + ".tmp", log_path)


if __name__ == "__main__":
    main()
