"""How soon the window shows the arm, and whether the physics keeps its ticks meanwhile.

`dora run` of the body's dataflow in GUI mode (bench/common.py run_dataflow, the prober in the
prompt's place), on this display or a fresh Xvfb server where none is reachable, `--runs`
times. Each run: seconds from `dora run` to the first joint_state; from the first joint_state
(the physics runs, and the window's process has just started) to the node's log line `window
open: it shows the arm ...` (looked for every 50 ms); and, while the window loads (after the
first WARMUP_S, as `so101 bench` counts), the joint_state rate and the ticks the node missed.
`--busy-cpu` keeps a busy loop on the CPU the window keeps to (the last one), as another
program on a busy machine would.

    .venv/bin/python bench/window_bench.py [--runs N] [--body pybullet|mujoco] [--busy-cpu]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

if __package__ in (None, ""):  # run as a script: the checkout holds `bench`
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import PACED_PROBE_ENV, WARMUP_S, run_dataflow, tick_figures  # noqa: E402
from so101.bodies.registry import SIMULATED_BODIES  # noqa: E402
from so101.runtime.argtypes import whole_number  # noqa: E402
from so101.runtime.display import display_available, virtual_display  # noqa: E402
from so101.runtime.dataflow import TICK_PERIOD_S  # noqa: E402
from so101.runtime.processes import stop_process  # noqa: E402

SHOWN_FOR_S = 1.0  # the run goes on this long after the window shows the arm


def window_start(record: dict) -> dict:
    """One GUI run's figures: start-up, the window's delay after it, the physics while the window loads."""
    first_state_ns = record["probe"]["first_state_ns"]
    shown_ns = record["measured_from_ns"]
    loading_from_ns = first_state_ns + int(WARMUP_S * 1e9)
    states_ns = [state[0] for state in record["probe"]["states"] if loading_from_ns <= state[0] < shown_ns]
    ticks = tick_figures([tick for tick in record["ticks"] if loading_from_ns <= tick[0] < shown_ns], TICK_PERIOD_S)
    return {
        "startup_s": (first_state_ns - record["started_ns"]) / 1e9,
        "window_shows_arm_s": (shown_ns - first_state_ns) / 1e9,
        "loading_joint_state_per_s": ((len(states_ns) - 1) / ((states_ns[-1] - states_ns[0]) / 1e9)
                                      if len(states_ns) > 1 else float("nan")),
        "loading_ticks_missed": ticks["ticks_missed"], "loading_ticks_served": ticks["ticks_served"],
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python bench/window_bench.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=whole_number(1, 1000), default=5, help="dora runs (default 5)")
    parser.add_argument("--body", choices=SIMULATED_BODIES, default="pybullet", help="whose window (default pybullet)")
    parser.add_argument("--busy-cpu", action="store_true", help="a busy loop on the CPU the window keeps to, meanwhile")
    args = parser.parse_args(argv)
    with contextlib.ExitStack() as stack:
        if args.busy_cpu:
            stack.enter_context(busy_last_cpu())
        return measure(args)


@contextlib.contextmanager
def busy_last_cpu():
    """A process spinning on the last CPU (the one so101.gui.viewer keeps to), stopped after."""
    spinner = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        if hasattr(os, "sched_setaffinity"):
            os.sched_setaffinity(spinner.pid, sorted(os.sched_getaffinity(0))[-1:])
        yield
    finally:
        stop_process(spinner, 5, first_signal=signal.SIGTERM)


def measure(args: argparse.Namespace) -> int:
    runs = []
    display = os.environ.get("DISPLAY") if display_available() else None
    shown_on = display or "Xvfb"
    for run in range(args.runs):
        load = os.getloadavg()[0]
        # A fresh Xvfb server for each run, as for a person starting the program.
        with (contextlib.nullcontext(display) if display else virtual_display()) as run_display, \
                tempfile.TemporaryDirectory(prefix="so101-window-bench-") as tmp:
            try:
                record = run_dataflow(Path(tmp) / "run", SHOWN_FOR_S, {"SO101_FAST_STEPS": "0", "SO101_MODE": "gui"},
                                      PACED_PROBE_ENV, display=run_display, body=args.body)
            except RuntimeError as error:  # no joint_state, or no window, within 60 s of `dora run`
                said = str(error).splitlines()[0].split(" (see ")[0]  # its temporary folder is gone
                print(f"run {run + 1} ({shown_on}, load {load:.2f}): {said} within 60 s of `dora run`", flush=True)
                continue
        figures = window_start(record)
        runs.append(figures)
        print(f"run {run + 1} ({shown_on}, load {load:.2f}): dora run -> first joint_state {figures['startup_s']:.2f} s, "
              f"-> window shows the arm {figures['window_shows_arm_s']:.2f} s; while it loads "
              f"{figures['loading_joint_state_per_s']:.2f} joint_state per s, ticks missed / served "
              f"{figures['loading_ticks_missed']} / {figures['loading_ticks_served']}", flush=True)
    if not runs:
        print(f"the window showed the arm in none of the {args.runs} runs")
        return 1
    shown_s = [figures["window_shows_arm_s"] for figures in runs]
    print(f"window shows the arm, s after the first joint_state (median | min | max of {len(runs)}"
          f"{f'; in {args.runs - len(runs)} more it did not show' if len(runs) < args.runs else ''}): "
          f"{statistics.median(shown_s):.2f} | {min(shown_s):.2f} | {max(shown_s):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
