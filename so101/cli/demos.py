"""`so101 demos DIR`: demonstrations of a task by the scripted expert, in lockstep, into a LeRobot dataset.

Episode i is laid out from seed S + i. By default only the episodes that succeed are written
(`--keep success`); the others are counted and reported. One line per episode, then
`demos: N episodes kept, K of M succeeded (P%), T s, X× real time`. The frames hold the task's
features (the arm's state and action, the objects' poses, success and reward) and, unless
`--no-video`, the front and wrist cameras, drawn for each frame's own state. A run that stops
part-way leaves every episode it saved; run it again on the same folder and it appends.
`--workers K` runs K dataflows at once, each on its share of the seeds, each keeping its episodes
in a spool (so101/dataset/spool.py); this command adds them to the dataset in seed order, so the
dataset is the one a single worker writes.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from so101.observe import OBSERVE_HELP
from so101.runtime.argtypes import add_camera_size_option, number, observed_list
from so101.launch.lockstep import (
    add_common_arguments, backdrop_lines, expert_driver, fail, flows_for, log_place, refuse_real, run_flows, unpictured_problem,
    work_folder,
)
from so101.launch.on_cluster import cluster_place
from so101.dataset.settings import DEFAULT_IMAGE_SIZE
from so101.runtime.lockstep import DEFAULT_LOCKSTEP_FPS
from so101.tasks.episodes import Outcome


class MergeFailed(Exception):
    """A worker's episode could not be added to the dataset (a full disk); str() is one line."""


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    parser.add_argument("dataset", type=Path, metavar="DIR", help="the dataset's folder: new, empty, or one made by so101 demos")
    add_common_arguments(parser)
    parser.add_argument("--keep", choices=("success", "all"), default="success",
                        help="which episodes are written (default success: failed ones are counted, not written)")
    parser.add_argument("--no-video", action="store_true", help="leave the cameras out (a state-only dataset)")
    parser.add_argument("--observe", type=observed_list, default=None, metavar="LIST", help=OBSERVE_HELP)
    add_camera_size_option(parser, DEFAULT_IMAGE_SIZE, "the cameras' picture size")
    parser.add_argument("--learner", type=Path, default=None, metavar="DIR",
                        help="DAgger: a trained state policy (a LeRobot folder, or so101 learn's) drives each episode "
                             "first, unwritten, and the expert takes over from where it left things at a moment drawn "
                             "from the seed; what is written is the expert's way on (an episode the learner finished "
                             "alone writes nothing). A seeing recipe's folder drives behind its eyes (the front picture "
                             "drawn in --looks), and the environment state written is what its eyes found")
    parser.add_argument("--takeover-s", type=number(lambda value: 0 < value <= 60, "seconds above 0, at most 60"),
                        default=None, metavar="S",
                        help="--learner: the expert takes over between 0 and S simulated seconds in (default 12)")
    parser.add_argument("--policy-python", type=Path, default=None, metavar="PY",
                        help="--learner: the Python that runs it, with LeRobot (default so101 policy-env's)")


def run(args: argparse.Namespace) -> int:
    from so101.dataset.features import IMAGE_KEY, WRIST_IMAGE_KEY, video_keys_and_sizes
    from so101.observe import OBSERVE_ENV_VAR, observed_for
    from so101.dataset.layout import DatasetError
    from so101.dataset.spool import pop, spooled
    from so101.dataset.writer import DatasetWriter
    from so101.tasks import task_named

    refusal = refuse_real("demos", args.body)
    if refusal:
        return fail(refusal)
    learner = None
    if args.learner is None and (args.takeover_s is not None or args.policy_python is not None):
        return fail(f"so101 demos: {'--takeover-s' if args.takeover_s is not None else '--policy-python'} goes with "
                    "--learner DIR")
    args.takeover_s = 12.0 if args.takeover_s is None else args.takeover_s
    if args.learner is not None:
        from so101.policy.choice import choose_policy

        try:
            learner = choose_policy(args.learner, args.policy_python, args.task, task_named(args.task).object_state_names)
        except ValueError as error:
            return fail(f"so101 demos: --learner: {error}")
        if learner.picture_size is not None:
            return fail(f"so101 demos: --learner {args.learner} sees pictures: a learner reads the arm and the objects "
                        "only (a state policy, or so101 learn's folder)")
    place = cluster_place(args, "the runners keep the episodes")
    if isinstance(place, str):
        return fail(f"so101 demos: {place}")
    root = args.dataset.expanduser().resolve()
    observed = args.observe or observed_for(task=True, video=not args.no_video)
    problem = observed.problem(task=True, video=not args.no_video)
    if problem:
        return fail(f"so101 demos: --observe {observed}: {problem}")
    picture_size = args.image_size if observed.front or observed.wrist else None
    # a seeing recipe's learner drives behind its eyes, which see the front picture at their size
    eyes_size = learner.body_pictures[1] if learner is not None else None
    if eyes_size is not None and picture_size not in (None, eyes_size):
        return fail(f"so101 demos: --learner {args.learner} sees through its eyes at {eyes_size[0]}x{eyes_size[1]}: "
                    f"record at --camera-size {eyes_size[0]}x{eyes_size[1]}, or give --no-video")
    problem = unpictured_problem(args, picture_size is not None or eyes_size is not None,
                                 "video (no --no-video), --observe with a camera, or a seeing recipe's --learner")
    if problem:
        return fail(f"so101 demos: {problem}")
    video_sizes = video_keys_and_sizes(picture_size, True, observed)
    merged = args.workers > 1
    try:  # another dataset's folder (other features, another rate) is refused here, before anything starts
        opened = DatasetWriter.open(root, DEFAULT_LOCKSTEP_FPS, video_sizes,
                                    environment_names=task_named(args.task).object_state_names,
                                    environment_state=observed.environment)
    except DatasetError as error:
        return fail(f"so101 demos: {error}")
    writer = opened if merged else None
    if not merged:  # the runner writes it
        opened.close()
    work = work_folder("demos")
    pictures = tuple(input_id for input_id, key in (("image", IMAGE_KEY), ("wrist_image", WRIST_IMAGE_KEY))
                     if key in video_sizes or (input_id == "image" and eyes_size is not None))
    # behind the eyes, what is written is what the eyes found: what the policy trained on it will read
    seen = {"SO101_ENVIRONMENT_SEEN": "1"} if eyes_size is not None and observed.environment else {}
    flows = flows_for(args, work, expert_driver(args, learner), pictures, picture_size or eyes_size,
                      lambda folder: {"SO101_SPOOL_DIR" if merged else "SO101_RECORD_DIR": str(folder / "spool" if merged else root),
                                      "SO101_KEEP": args.keep, OBSERVE_ENV_VAR: str(observed), **seen})
    cameras = (f"{' and '.join(name for name in ('front', 'wrist') if getattr(observed, name))} {flows[0].picture_size}"
               if picture_size else "no video")
    workers = f", {args.workers} workers merged in seed order" if merged else ""
    behind_eyes = (f" behind its eyes (front {eyes_size[0]}x{eyes_size[1]}, looks {args.looks}; the environment "
                   "state written is what they found)" if eyes_size is not None else "")
    taking_over = (f", taking over from the learner {learner.folder}{behind_eyes} between 0 and {args.takeover_s:g} s in"
                   if learner is not None else "")
    print(f"demos: {args.task} on {args.body} by the expert (noise {args.noise:g}, misses {args.misses:g}{taking_over}), seeds {args.seed}.."
          f"{args.seed + args.episodes - 1}, observing {observed} ({cameras}), into {root}{workers} "
          f"(logs: {log_place(args, work)})", flush=True)
    for line in backdrop_lines(args, picture_size):
        print(f"demos: {line}", flush=True)
    started = time.monotonic()
    kept = 0

    def show(outcome: Outcome, worker: int) -> None:
        """With workers, this command writes the dataset from their spools, an episode as soon as every
        one before it is in: a stop part-way leaves whole episodes, in seed order."""
        nonlocal kept
        if outcome.kept and writer is not None:
            try:
                pop(spooled(Path(flows[worker].runner_env["SO101_SPOOL_DIR"]))[0], writer)
            except (DatasetError, IndexError, OSError) as error:  # the workers are stopped on the way out
                raise MergeFailed(f"episode {outcome.index} (seed {outcome.seed}) could not be added: {error}") from None
        kept += outcome.kept
        print(outcome.line(), flush=True)

    try:
        outcomes, problem = run_flows("demos", flows, work, args.log, show, place)
    except MergeFailed as error:
        return fail(f"so101 demos: {error} ({kept} episodes were kept before it)")
    finally:
        if writer is not None:
            writer.close()
    wall_s = time.monotonic() - started
    if problem:
        return fail(f"so101 demos: {problem} ({kept} episodes were kept before it)")
    successes = sum(outcome.success for outcome in outcomes)
    simulated_s = sum(outcome.frames for outcome in outcomes) / DEFAULT_LOCKSTEP_FPS
    print(f"demos: {kept} episodes kept, {successes} of {len(outcomes)} succeeded "
          f"({100 * successes / len(outcomes):.0f}%), {wall_s:.1f} s, {simulated_s / wall_s:.1f}× real time", flush=True)
    return 0
