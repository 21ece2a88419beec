"""`so101`: the command-line entry point.

Each subcommand lives in its own module with `add_arguments(parser)` and
`run(args) -> int`; this file only lists them and turns known failures into
one-line errors.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from so101.assets import ModelFilesError
from so101.runtime.display import DisplayError

# name -> (module, one-line help)
SUBCOMMANDS = {
    "assets": ("so101.cli.assets", "fetch the SO-101 model (URDF + meshes) and verify it"),
    "inspect": ("so101.cli.course_steps", "course step A: load the arm and print its joint table"),
    "joints": ("so101.cli.course_steps", "course step B: drive joints 0-4 and print the angles reached"),
    "plot-step": ("so101.cli.plot_step", "exercise 2: plot one joint's step response for a few damping values (PNG)"),
    "bench": ("so101.cli.bench", "benchmark the simulation node's 4 ms real-time budget against raw PyBullet (JSON + table)"),
    "snapshot": ("so101.cli.snapshot", "render the arm in a pose to a PNG, headless (no window needed)"),
    "reach": ("so101.cli.reach", "check IK and the simulated arm against Cartesian targets: tip errors in mm (table, JSON)"),
    "calibrate": ("so101.cli.calibrate", "calibrate a real SO-101 follower (or --leader: leader) arm into LeRobot's calibration format (JSON)"),
    "cluster-demo": ("so101.cli.cluster", "the dataflow on a dora cluster: two daemons on this machine, the prompt on the second"),
    "cluster-dataflow": ("so101.cli.cluster", "write the dataflow for a dora cluster of two machines: the body on `arm`, the prompt on `desk`"),
    "teleop": ("so101.cli.teleop", "steps D + exercise 1: the dataflow and the keyboard prompt in one terminal"),
    "dataset": ("so101.cli.dataset", "summarize a LeRobot dataset (episodes, frames, tasks, features); --plot N draws an episode"),
    "replay": ("so101.cli.replay", "play an episode of a LeRobot dataset onto any body, then print the tracking error"),
    "demos": ("so101.cli.demos", "demonstrations of a task by the scripted expert, in lockstep, into a LeRobot dataset"),
    "eval": ("so101.cli.evaluate", "score the expert, an idle arm or a trained policy on a task's seeded layouts, in lockstep: success rate with its 95% interval"),
    "learn": ("so101.cli.learn", "from nothing to a trained policy: demonstrations, (--sees) eyes taught by the simulator, lerobot-train; prints the folder --policy takes"),
    "policy-env": ("so101.cli.policy_env", "build (once) and check the environment that runs trained LeRobot policies (--policy-python)"),
    "physics": ("so101.cli.physics", "the ranges varied physics draws from, and why; --fit measures a recording's servos "
                "(delay, speed limit, time constant, sag) and writes ranges centred on them"),
    "cameras": ("so101.cli.cameras", "list the cameras (V4L2: path, name, sizes and frame rates), save a picture from "
                "each; print, fit (--fit) and line up (--align) where a camera stands against the simulated one"),
    "fake-arm": ("so101.cli.fake_arm", "an emulated SO-101 servo bus on a pseudo-terminal, for trying the real-arm driver without hardware"),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="so101",
        description="The SO-101 arm in PyBullet, driven through a dora-rs dataflow (course section 10.2).",
    )
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, (module_name, summary) in SUBCOMMANDS.items():
        module = importlib.import_module(module_name)
        sub = commands.add_parser(name, help=summary.replace("%", "%%"), description=summary)  # help is %-formatted
        module.add_arguments(sub, name)
        sub.set_defaults(run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.run(args) or 0
    except (ModelFilesError, DisplayError) as error:
        print(f"so101 {args.command}: {error}", file=sys.stderr)
        return 2
    except OSError as error:  # a file that cannot be written or read (--out in a folder that is a file, ...)
        where = f"{error.filename}: " if error.filename else ""
        print(f"so101 {args.command}: cannot use {where}{error.strerror or error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
