"""`so101 bench`: the simulation node's real-time budget against raw PyBullet.

The benchmark is the package bench/ at the top of the project (bench/run_bench.py), next to
nodes/ and dataflow.yml, which it runs; this command imports it and passes the options on.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from so101.runtime.dataflow import ROOT

BENCH_SCRIPT = ROOT / "bench" / "run_bench.py"


def bench_module():
    """bench.run_bench, imported from this checkout (`so101` builds every subcommand's parser: once)."""
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    return importlib.import_module("bench.run_bench")


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    if BENCH_SCRIPT.is_file():
        bench_module().add_arguments(parser)


def run(args: argparse.Namespace) -> int:
    if not BENCH_SCRIPT.is_file():
        print(f"so101 bench: {BENCH_SCRIPT} is missing; `so101 bench` runs from a checkout of the project", file=sys.stderr)
        return 2
    return bench_module().run(args)
