"""Run by the policy environment's Python (LeRobot 0.4.4; tests/test_real_cameras.py): LeRobot's own
LeRobotDataset loads a dataset this project recorded, offline, its video decoded with PyAV (the backend
every install has), and says what came back, as JSON on stdout.

argv: the dataset's folder. stdout (last line): {"frames": the dataset's frame count, "episodes": its
episode count, "items": {video key: [[frame index, the decoded picture's shape], ...]}}, for the first,
middle and last frames.
"""

import json
import os
import sys

os.environ.setdefault("HF_HUB_OFFLINE", "1")  # a local dataset needs no network; never fetch

from lerobot.datasets.lerobot_dataset import LeRobotDataset  # noqa: E402


def main() -> None:
    dataset = LeRobotDataset("local/recorded", root=sys.argv[1], video_backend="pyav")
    last = dataset.num_frames - 1
    indices = sorted({0, last // 2, last})
    items = {index: dataset[index] for index in indices}
    print(json.dumps({"frames": dataset.num_frames, "episodes": dataset.num_episodes,
                      "items": {key: [[index, list(items[index][key].shape)] for index in indices]
                                for key in dataset.meta.video_keys}}))


if __name__ == "__main__":
    main()
