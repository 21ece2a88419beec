"""How far a trained policy's arm angles are from a dataset's at the moment its jaws close: a check to
run by hand with a policy environment's Python (`so101 policy-env`), never the project's own (the
test suite does not run it).

    ~/.cache/so101/policy-env-lerobot-0.4.4/bin/python tools/grasp_error.py POLICY_DIR DATASET_DIR

For each episode of the dataset (say, `so101 demos` on layouts the policy never saw), it finds the
grasp: the first frame whose gripper action crosses halfway from the episode's most open to its
most closed. Then, frame by frame as the dataset holds them (the policy is never off the
demonstration's path: no simulator), it asks the policy for an action chunk at every 4th frame
whose chunk reaches the grasp, and compares the chunk's action for the grasp frame with the
dataset's. A pan off by 3° puts the jaws about 12 mm aside at 0.23 m, about what the cube's grasp
tolerates (docs/loop/policy.md). Prints, per episode, the dataset's pan at the grasp and the
mean signed error of each arm joint (policy minus dataset, degrees); then the median and the 90th
percentile over episodes of the largest error seen per joint, and a straight line fitted to the pan's
error against the pan (a policy that reads the cube's place too weakly errs in proportion).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

os.environ.setdefault("HF_HUB_OFFLINE", "1")  # a local dataset and policy need no network; never fetch

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT)]

from so101.policy.loaded import LoadedPolicy, PolicyFailed  # noqa: E402 (the policy node's own loading, pre- and post-processors)

from so101.dataset.features import ACTION_KEY, ENVIRONMENT_KEY, MOTOR_NAMES, STATE_KEY  # noqa: E402
from so101.dataset.layout import DatasetError  # noqa: E402
from so101.dataset.reader import Dataset  # noqa: E402

ARM = MOTOR_NAMES[:5]
EVERY = 4  # frames between the chunk starts compared


def grasp_frame(gripper: np.ndarray) -> int | None:
    """The first frame whose gripper action has crossed halfway from open to closed, after being open."""
    halfway = (gripper.max() + gripper.min()) / 2
    was_open = False
    for frame, value in enumerate(gripper):
        if value >= halfway:
            was_open = True
        elif was_open:
            return frame
    return None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("policy", type=Path, help="a policy folder, .../checkpoints/last/pretrained_model")
    parser.add_argument("dataset", type=Path, help="a state-only dataset of the task the policy learned")
    args = parser.parse_args()
    try:
        dataset = Dataset.open(args.dataset.expanduser())
    except DatasetError as error:
        print(error, file=sys.stderr)
        return 1
    missing = [key for key in (STATE_KEY, ENVIRONMENT_KEY, ACTION_KEY) if key not in dataset.features]
    if missing or not dataset.episodes:
        print(f"{args.dataset} is not a task's state-only dataset with episodes (it lacks {', '.join(missing) or 'episodes'})",
              file=sys.stderr)
        return 1
    try:
        loaded = LoadedPolicy(args.policy.expanduser(), "cpu", "")
    except PolicyFailed as error:
        print(error, file=sys.stderr)
        return 1

    def observe(frames: dict[str, np.ndarray], frame: int) -> dict[str, np.ndarray]:
        return {key: frames[key][frame].astype(np.float32) for key in (STATE_KEY, ENVIRONMENT_KEY)}

    largest, pans, chunk_size = [], [], 0
    for episode in (summary.index for summary in dataset.episodes):
        frames = dataset.episode_frames(episode)
        actions = frames[ACTION_KEY]
        chunk_size = chunk_size or len(loaded.chunk(observe(frames, 0)))
        grasp = grasp_frame(actions[:, len(ARM)])
        if grasp is None:
            print(f"episode {episode}: the jaws never close")
            continue
        errors = []
        for start in range(max(0, grasp - chunk_size + 1), grasp + 1, EVERY):
            errors.append(loaded.chunk(observe(frames, start))[grasp - start, :len(ARM)] - actions[grasp, :len(ARM)])
        signed = np.mean(errors, axis=0)
        pans.append((actions[grasp, 0], signed[0]))
        largest.append(np.abs(errors).max(axis=0))
        print(f"episode {episode}: pan {actions[grasp, 0]:+.1f}° at frame {grasp}; error "
              + ", ".join(f"{name} {error:+.2f}°" for name, error in zip(ARM, signed)))
    if not largest:
        return 1
    for label, share in (("median", 50), ("90th percentile", 90)):
        print(f"{label} over {len(largest)} episodes of the largest error: "
              + ", ".join(f"{name} {error:.2f}°" for name, error in zip(ARM, np.percentile(largest, share, axis=0))))
    pan, pan_error = np.array(pans).T
    slope, offset = np.polyfit(pan, pan_error, 1)
    print(f"the pan's error against the pan, a straight line through the episodes: {slope:+.3f}° a degree, "
          f"0 at {-offset / slope:+.1f}°, correlation {np.corrcoef(pan, pan_error)[0, 1]:+.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
