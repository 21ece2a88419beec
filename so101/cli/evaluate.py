"""`so101 eval`: score a driver on a task's seeded layouts, in lockstep, as a success rate with its interval.

One line per episode (seed, success, time to success), then
`success: K/N (P%, 95% CI lo–hi, Wilson), mean time to success T s`. A score is a measurement:
the exit code is 0 whatever it is; bad options and a dataflow that fails exit non-zero with
one line. `--expert` scores the scripted expert (nodes/expert.py), `--idle` an arm held at
home: the floor every score must beat. `--video DIR` keeps each episode's front camera as an
mp4 (seed_S.mp4), to see why an episode failed. `--workers K` runs K dataflows at once, each on
its share of the seeds; the lines still come in seed order.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from so101.cli.argtypes import image_size
from so101.cli.lockstep_run import add_common_arguments, cluster_place, fail, flows_for, log_place, refuse_real, run_flows, work_folder
from so101.dataset.settings import DEFAULT_IMAGE_SIZE
from so101.tasks.episodes import score_line


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    driver = parser.add_mutually_exclusive_group(required=True)
    driver.add_argument("--expert", action="store_true", help="the scripted expert drives (nodes/expert.py)")
    driver.add_argument("--idle", action="store_true", help="nothing drives: the arm holds home (the floor of any score)")
    add_common_arguments(parser)
    parser.add_argument("--video", type=Path, default=None, metavar="DIR",
                        help="keep each episode's front camera as an mp4 in DIR (drawn every frame: slower)")
    parser.add_argument("--image-size", type=image_size, default=DEFAULT_IMAGE_SIZE, metavar="WxH",
                        help=f"--video's picture size (default {DEFAULT_IMAGE_SIZE})")


def run(args: argparse.Namespace) -> int:
    refusal = refuse_real("eval", args.body)
    if refusal:
        return fail(refusal)
    place = cluster_place(args)
    if isinstance(place, str):
        return fail(f"so101 eval: {place}")
    work = work_folder("eval")
    video = str(args.video.expanduser().resolve()) if args.video is not None else ""
    flows = flows_for(args, work, args.expert, ("image",), args.image_size if video else None,
                      lambda folder: {"SO101_VIDEO_DIR": video})
    driver = "the expert" if args.expert else "idle (the arm held at home)"
    print(f"eval: {args.task} on {args.body}, {driver}, seeds {args.seed}..{args.seed + args.episodes - 1}, "
          f"time limit {args.time_limit:g} s, {args.workers} worker{'s' if args.workers > 1 else ''} "
          f"(logs: {log_place(args, work)})", flush=True)
    outcomes, problem = run_flows("eval", flows, work, args.log, lambda outcome, worker: print(outcome.line(), flush=True),
                                  place)
    if problem:
        return fail(f"so101 eval: {problem}")
    print(score_line(outcomes), flush=True)
    return 0
