"""`so101 bench`: the simulation node's real-time budget against raw PyBullet.

The benchmark is bench/run_bench.py at the top of the project, next to nodes/ and
dataflow.yml, which it runs; this command loads it and passes the options on.
"""

from __future__ import annotations

import argparse
import functools
import importlib.util
import sys
from pathlib import Path

BENCH_SCRIPT = Path(__file__).resolve().parents[2] / "bench" / "run_bench.py"


@functools.cache  # `so101` builds every subcommand's parser: load the script once
def _bench_module():
    spec = importlib.util.spec_from_file_location("so101_bench_script", BENCH_SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    if BENCH_SCRIPT.is_file():
        _bench_module().add_arguments(parser)


def run(args: argparse.Namespace) -> int:
    if not BENCH_SCRIPT.is_file():
        print(f"so101 bench: {BENCH_SCRIPT} is missing; `so101 bench` runs from a checkout of the project", file=sys.stderr)
        return 2
    return _bench_module().run(args)
