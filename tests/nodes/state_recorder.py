"""A test node: records every joint_state it receives, with its arrival time, to $RECORD_FILE (JSON) at STOP."""

import json
import os
import time

from dora import Node


def main() -> None:
    record_path = os.environ["RECORD_FILE"]
    samples = []
    for event in Node():
        if event["type"] == "INPUT" and event["id"] == "joint_state":
            samples.append([time.monotonic(), event["value"].to_pylist()])
        elif event["type"] == "STOP":
            break
    with open(record_path + ".tmp", "w") as handle:
        json.dump({"samples": samples}, handle)
    os.replace(record_path + ".tmp", record_path)


if __name__ == "__main__":
    main()
