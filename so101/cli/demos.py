"""`so101 demos DIR`: demonstrations of a task by the scripted expert, in lockstep, into a LeRobot dataset.

Episode i is laid out from seed S + i. By default only the episodes that succeed are written
(`--keep success`); the others are counted and reported. One line per episode, then
`demos: N episodes kept, K of M succeeded (P%), T s, X× real time`. The frames hold the task's
features (the arm's state and action, the objects' poses, success and reward) and, unless
`--no-video`, the front and wrist cameras, drawn for each frame's own state. A run that stops
part-way leaves every episode it saved; run it again on the same folder and it appends.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from so101.cli.argtypes import image_size
from so101.cli.lockstep_run import add_common_arguments, fail, flow_for, refuse_real, run_flow, work_folder
from so101.dataset.settings import DEFAULT_IMAGE_SIZE
from so101.runtime.lockstep import DEFAULT_LOCKSTEP_FPS


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    parser.add_argument("dataset", type=Path, metavar="DIR", help="the dataset's folder: new, empty, or one made by so101 demos")
    add_common_arguments(parser)
    parser.add_argument("--keep", choices=("success", "all"), default="success",
                        help="which episodes are written (default success: failed ones are counted, not written)")
    parser.add_argument("--no-video", action="store_true", help="leave the cameras out (a state-only dataset)")
    parser.add_argument("--image-size", type=image_size, default=DEFAULT_IMAGE_SIZE, metavar="WxH",
                        help=f"the cameras' picture size (default {DEFAULT_IMAGE_SIZE})")


def run(args: argparse.Namespace) -> int:
    from so101.dataset.features import video_keys_and_sizes
    from so101.dataset.layout import DatasetError
    from so101.dataset.writer import DatasetWriter
    from so101.tasks import task_named

    refusal = refuse_real("demos", args.body)
    if refusal:
        return fail(refusal)
    root = args.dataset.expanduser().resolve()
    picture_size = None if args.no_video else args.image_size
    try:  # another dataset's folder (other features, another rate) is refused here, before anything starts
        DatasetWriter.open(root, DEFAULT_LOCKSTEP_FPS, video_keys_and_sizes(picture_size, True),
                           environment_names=task_named(args.task).object_state_names).close()
    except DatasetError as error:
        return fail(f"so101 demos: {error}")
    work = work_folder("demos")
    flow = flow_for(args, work, True, ("image", "wrist_image"), picture_size, SO101_RECORD_DIR=str(root),
                    SO101_KEEP=args.keep)
    cameras = f"front and wrist {flow.picture_size}" if flow.picture_size else "no video"
    print(f"demos: {args.task} on {args.body} by the expert (noise {args.noise:g}), seeds {args.seed}.."
          f"{args.seed + args.episodes - 1}, {cameras}, into {root} (log: {args.log or work / 'run.log'})", flush=True)
    started = time.monotonic()
    outcomes, problem = run_flow("demos", flow, work, args.log, lambda outcome: print(outcome.line(), flush=True))
    wall_s = time.monotonic() - started
    kept = sum(outcome.kept for outcome in outcomes)
    if problem:
        return fail(f"so101 demos: {problem} ({kept} episodes were kept before it)")
    successes = sum(outcome.success for outcome in outcomes)
    simulated_s = sum(outcome.frames for outcome in outcomes) / DEFAULT_LOCKSTEP_FPS
    print(f"demos: {kept} episodes kept, {successes} of {len(outcomes)} succeeded "
          f"({100 * successes / len(outcomes):.0f}%), {wall_s:.1f} s, {simulated_s / wall_s:.1f}× real time", flush=True)
    return 0
