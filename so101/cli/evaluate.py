"""`so101 eval`: score a driver on a task's seeded layouts, in lockstep, as a success rate with its interval.

One line per episode (seed, success, time to success), then
`success: K/N (P%, 95% CI lo–hi, Wilson), mean time to success T s`. A score is a measurement:
the exit code is 0 whatever it is; bad options and a dataflow that fails exit non-zero with
one line. `--expert` scores the scripted expert (nodes/expert.py), `--idle` an arm held at
home: the floor every score must beat, `--policy DIR` a trained LeRobot policy (nodes/policy.py,
run by the Python of a policy environment: `so101 policy-env`, or `--policy-python`); the body
draws the pictures the policy sees, and in lockstep inference costs no simulated time.
`--video DIR` keeps each episode's front camera as an mp4 (seed_S.mp4), to see why an episode
failed. `--workers K` runs K dataflows at once, each on
its share of the seeds; the lines still come in seed order. On a cluster (`--coordinator`, `--machine`),
`--policy-machine NAME` runs every worker's policy on daemon NAME and its body and runner on this machine's.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from so101.policy.settings import torch_device
from so101.runtime.argtypes import add_camera_size_option
from so101.launch.lockstep import (
    Driver, add_common_arguments, backdrop_lines, expert_driver, fail, flows_for, log_place, refuse_real, run_flows,
    unpictured_problem, work_folder,
)
from so101.launch.on_cluster import add_policy_machine_argument, cluster_place
from so101.dataset.settings import DEFAULT_IMAGE_SIZE
from so101.policy.environment import default_dir, python_in
from so101.runtime.dataflow import POLICY_NODE_FILE
from so101.tasks.episodes import inference_line, score_line


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    driver = parser.add_mutually_exclusive_group(required=True)
    driver.add_argument("--expert", action="store_true", help="the scripted expert drives (nodes/expert.py)")
    driver.add_argument("--idle", action="store_true", help="nothing drives: the arm holds home (the floor of any score)")
    driver.add_argument("--policy", type=Path, default=None, metavar="DIR",
                        help="a trained LeRobot policy drives (nodes/policy.py): its folder as lerobot-train writes it, "
                             ".../checkpoints/last/pretrained_model")
    parser.add_argument("--policy-python", type=Path, default=None, metavar="PY",
                        help=f"--policy: the Python that runs it, with LeRobot (default {python_in(default_dir())}, "
                             "which so101 policy-env makes)")
    parser.add_argument("--policy-device", type=torch_device, default="cpu", metavar="DEVICE",
                        help="--policy: the torch device it runs on: cpu (default), cuda or mps")
    add_common_arguments(parser)
    add_policy_machine_argument(parser)
    parser.add_argument("--video", type=Path, default=None, metavar="DIR",
                        help="keep each episode's front camera as an mp4 in DIR (drawn every frame: slower)")
    add_camera_size_option(parser, DEFAULT_IMAGE_SIZE, "--video's picture size, and a policy that sees gets its cameras' "
                                                       "pictures at its own size")


def run(args: argparse.Namespace) -> int:
    refusal = refuse_real("eval", args.body)
    if refusal:
        return fail(refusal)
    if args.policy_machine and args.policy is None:
        return fail(f"so101 eval: --policy-machine {args.policy_machine} places the policy: it goes with --policy DIR")
    place = cluster_place(args, "the runners keep the episodes")
    if isinstance(place, str):
        return fail(f"so101 eval: {place}")
    video = str(args.video.expanduser().resolve()) if args.video is not None else ""
    pictures: tuple[str, ...] = ("image",)
    picture_size = args.image_size if video else None
    driver: Driver | None
    if not args.expert and (args.noise or args.misses):
        return fail("so101 eval: --noise and --misses are the scripted expert's: they go with --expert")
    if args.policy is not None:
        chosen = policy_driver(args)
        if isinstance(chosen, str):
            return fail(f"so101 eval: {chosen}")
        driver, (seen, seen_size) = chosen
        if seen_size is not None:  # the body draws what the policy (or its eyes) sees, at the size it learned from
            pictures, picture_size = seen, seen_size
    elif args.policy_python is not None:
        return fail("so101 eval: --policy-python goes with --policy DIR")
    else:
        driver = expert_driver(args) if args.expert else None
    problem = unpictured_problem(args, picture_size is not None, "--video FILE, or a --policy that sees")
    if problem:
        return fail(f"so101 eval: {problem}")
    work = work_folder("eval")
    flows = flows_for(args, work, driver, pictures, picture_size, lambda folder: {"SO101_VIDEO_DIR": video})
    who = ("the expert" if args.expert else f"the policy in {args.policy}" if args.policy is not None
           else "idle (the arm held at home)")
    if args.policy_machine:
        who += f" on machine {args.policy_machine!r}"
    print(f"eval: {args.task} on {args.body}, {who}, seeds {args.seed}..{args.seed + args.episodes - 1}, "
          f"time limit {args.time_limit:g} s, {args.workers} worker{'s' if args.workers > 1 else ''} "
          f"(logs: {log_place(args, work)})", flush=True)
    for line in backdrop_lines(args, picture_size):
        print(f"eval: {line}", flush=True)
    outcomes, problem = run_flows("eval", flows, work, args.log, lambda outcome, worker: print(outcome.line(), flush=True),
                                  place)
    if problem:
        return fail(f"so101 eval: {problem}")
    print(score_line(outcomes), flush=True)
    inference = inference_line(outcomes)
    if inference:
        print(f"{inference} (on {args.policy_device})", flush=True)
    return 0


def policy_driver(args: argparse.Namespace) -> tuple[Driver, tuple[tuple[str, ...], tuple[int, int] | None]] | str:
    """The policy node as the driver (with the eyes beside it, for a seeing recipe), and the pictures the
    body draws for them with their size (none: None); or what is wrong, in one line (so101.policy.choice)."""
    from so101.policy.choice import choose_policy
    from so101.tasks import task_named

    try:
        chosen = choose_policy(args.policy, args.policy_python, args.task, task_named(args.task).object_state_names,
                               python_elsewhere=args.policy_machine is not None)
    except ValueError as error:
        return str(error)
    for line in chosen.notes(args.backdrops, args.camera_poses):
        print(f"so101 eval: {line}", flush=True)
    print(f"so101 eval: {chosen.reads()}", flush=True)
    driver = Driver("policy", POLICY_NODE_FILE, chosen.inputs, chosen.env(args.task, args.policy_device),
                    python=str(chosen.python),
                    perception_env=chosen.perception_env(args.lang) if chosen.recipe else None)
    return driver, chosen.body_pictures
