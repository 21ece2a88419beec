"""A test node: sends one joint_cmd each time the test creates its trigger file.

$JOINT_CMD holds the angles (space-separated degrees, sent as float64).
On each `tick` it looks for $TRIGGER_FILE; when present, it sends the command,
deletes the file and prints "sent joint_cmd N", so a test decides exactly when
the arm moves (before/after screenshots, after a restart).
"""

import os

import pyarrow as pa
from dora import Node


def main() -> None:
    trigger = os.environ["TRIGGER_FILE"]
    command = pa.array([float(word) for word in os.environ["JOINT_CMD"].split()], type=pa.float64())
    sent = 0
    node = Node()
    for event in node:
        if event["type"] == "INPUT" and event["id"] == "tick" and os.path.exists(trigger):
            os.remove(trigger)
            sent += 1
            node.send_output("joint_cmd", command)
            print(f"sent joint_cmd {sent}", flush=True)
        elif event["type"] == "STOP":
            break


if __name__ == "__main__":
    main()
