"""The servo fit (so101.bodies.servo_fit) against a known answer: episodes of `so101 demos --physics varied`,
each fitted alone, the fitted delay against the command delay its seed drew (meta/info.json keeps it).

    python tools/fit_known_physics.py DATASET [--episodes N]

Prints one row per episode and the share recovered within one frame. The expert never turns a joint at
its speed limit, so these episodes cannot tell the limit (the fit says "none reached"); the suite's
tests/test_servo_fit.py recovers a limit from a servo driven past it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from so101.bodies.physics import physics_from_metadata  # noqa: E402
from so101.bodies.servo_fit import fit_joint  # noqa: E402
from so101.dataset.features import ACTION_KEY, STATE_KEY  # noqa: E402
from so101.dataset.layout import episode_scenario  # noqa: E402
from so101.dataset.reader import Dataset  # noqa: E402
from so101.robot import ARM_JOINTS  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset", type=Path)
    parser.add_argument("--episodes", type=int, default=20)
    args = parser.parse_args()
    dataset = Dataset.open(args.dataset)
    units = dataset.joint_units()
    within = 0
    print("| episode | drawn delay (frames) | fitted (median of the 5 arm joints) | p50 before → after (deg) |")
    print("|---|---|---|---|")
    for episode in dataset.episodes[:args.episodes]:
        physics = physics_from_metadata(episode_scenario(dataset.info, episode.index)["physics"])
        assert physics is not None, "a dataset of --physics varied"
        joints = dataset.episode_joints_deg(episode.index, units)
        fits = [fit_joint(joint.name, [(joints[ACTION_KEY][:, number], joints[STATE_KEY][:, number])], dataset.fps)
                for number, joint in enumerate(ARM_JOINTS)]
        drawn = physics.command_delay_s * dataset.fps
        fitted = float(np.median([fit.delay_frames for fit in fits]))
        within += abs(fitted - drawn) <= 1.0
        print(f"| {episode.index} | {drawn:.2f} | {fitted:g} | {np.median([f.error_before_deg for f in fits]):.2f} → "
              f"{np.median([f.error_after_deg for f in fits]):.2f} |")
    count = min(args.episodes, len(dataset.episodes))
    print(f"\nwithin one frame: {within}/{count}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
