"""How often an episode's videos show a new picture: for each video of a LeRobot dataset's episode,
how many of its frames differ from the frame before (mean absolute difference above a threshold).

    .venv/bin/python tools/picture_changes.py DATASET_DIR [--episode N] [--threshold LEVELS]

A camera that keeps up gives a new picture at every frame while the arm moves; one that falls
behind repeats the last picture until it draws the next (docs/loop/task.md says why).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from so101.dataset.layout import DatasetError, video_keys  # noqa: E402
from so101.dataset.reader import Dataset  # noqa: E402
from so101.dataset.video import new_pictures  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="tools/picture_changes.py", description=__doc__.splitlines()[0])
    parser.add_argument("dataset", type=Path, help="a LeRobot v3.0 dataset's folder")
    parser.add_argument("--episode", type=int, default=0, help="the episode (default 0)")
    parser.add_argument("--threshold", type=float, default=0.05,
                        help="mean absolute difference, in grey levels, that makes a picture new (default 0.05: a "
                             "repeated picture decodes the same to the level; bench/record_bench.py says why)")
    args = parser.parse_args(argv)
    try:
        dataset = Dataset.open(args.dataset)
        length = dataset.episodes[args.episode].length
    except (DatasetError, IndexError) as error:
        print(f"picture_changes: {error or f'no episode {args.episode}'}", file=sys.stderr)
        return 2
    for key in video_keys(dataset.features):
        print(f"{key}: {new_pictures(dataset.episode_images(args.episode, key), args.threshold)} new pictures in {length} frames "
              f"({length / dataset.fps:.1f} s at {dataset.fps} fps)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
