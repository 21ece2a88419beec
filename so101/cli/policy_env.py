"""`so101 policy-env [DIR]`: the environment that runs trained policies (LeRobot 0.4.4, torch, dora-rs).

Built once per machine, by default in the user's cache; run again, it only checks that what the
policy node imports imports, offline. Its last line names the interpreter to give `--policy-python`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from so101.policy.environment import REQUIREMENTS, PolicyEnvError, build, default_dir


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    parser.add_argument("folder", type=Path, nargs="?", default=None, metavar="DIR",
                        help=f"where the environment goes (default {default_dir()})")
    parser.add_argument("--python", default=sys.executable, metavar="PY",
                        help="the Python that makes it (default this one, 3.11: LeRobot 0.4.4 is the last for 3.11)")


def run(args: argparse.Namespace) -> int:
    folder = (args.folder or default_dir()).expanduser().resolve()
    print(f"policy environment in {folder}: {', '.join(REQUIREMENTS)} (a first build downloads several GB)",
          flush=True)
    try:
        env = build(folder, args.python, say=lambda line: print(line, flush=True))
    except PolicyEnvError as error:
        print(f"so101 policy-env: {error}", file=sys.stderr)
        return 1
    print(f"ready: {env.line()}")
    print(f"use it with: --policy-python {env.python}")
    return 0
