"""`python -m so101.perception.teach`: train the eyes on drawn pictures (so101 learn runs it in the policy
environment, where PyTorch is). One line per 250 steps; the held-out errors every 1,000 and at the end."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m so101.perception.teach", description=__doc__)
    parser.add_argument("--pictures", type=Path, nargs="+", required=True, help="the training pictures (.npz)")
    parser.add_argument("--held-out", type=Path, default=None, help="pictures to measure on (.npz)")
    parser.add_argument("--out", type=Path, required=True, help="the eyes' folder to write (eyes.pt, eyes.json)")
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)
    import torch

    from so101.perception.training import load_pictures, train_eyes

    torch.set_num_threads(args.threads)
    held_out = load_pictures([args.held_out]) if args.held_out else None
    result = train_eyes(load_pictures(args.pictures), held_out, args.out, args.steps, seed=args.seed,
                        say=lambda line: print(line, flush=True))
    print("eyes: held out: " + ", ".join(f"{key} {value:.2f}" for key, value in result.items()), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
