"""`python -m so101.perception.draw DATASET OUT.npz`: draw the eyes' training pictures from a dataset's
frames (so101.perception.pictures), in this project's Python (the renderer is MuJoCo's)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from so101.bodies.looks import LOOKS_CHOICES
from so101.bodies.scenario import Scenario, parse_scenario
from so101.perception.pictures import draw_pictures, read_frames
from so101.runtime.argtypes import image_size, parsed_by


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m so101.perception.draw", description=__doc__)
    parser.add_argument("dataset", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--count", type=int, default=15000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--looks", choices=LOOKS_CHOICES, default="varied")
    parser.add_argument("--size", type=image_size, default=(160, 120))
    parser.add_argument("--scenario", type=parsed_by(parse_scenario), default=Scenario(), metavar="JSON",
                        help="the camera poses and backdrops to draw from (so101.bodies.scenario; its looks are "
                             "--looks')")
    parser.add_argument("--pool-share", type=float, default=0.0, metavar="SHARE",
                        help="the share of pictures drawn over the backdrop pool (so101.bodies.backdrop_pool) where "
                             "the scenario gives the front camera no backdrop (default 0)")
    parser.add_argument("--held-out", action="store_true",
                        help="pictures to measure on: looks and layouts from seeds the training pictures never draw")
    args = parser.parse_args(argv)
    if not 0.0 <= args.pool_share <= 1.0:
        parser.error(f"--pool-share is a share from 0 to 1, not {args.pool_share}")
    started = time.monotonic()
    drawn = draw_pictures(read_frames(args.dataset), args.count, args.seed, tuple(args.size), args.looks,
                          held_out=args.held_out, poses=args.scenario.camera_poses, backdrops=args.scenario.backdrops,
                          pool_share=args.pool_share)
    partial = args.out.with_name(args.out.name + ".part.npz")
    np.savez(partial, **drawn)  # type: ignore[arg-type]  # numpy's stub reads a keyword as allow_pickle
    partial.replace(args.out)  # whole or not at all: a stopped run leaves no half file under the name
    print(f"pictures: {args.count} drawn in {time.monotonic() - started:.0f} s into {args.out}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
