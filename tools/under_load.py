"""The emulated-hardware tests under load: the check that the suite cannot starve.

    .venv/bin/python tools/under_load.py                 # 2 CPU-bound processes, the tests twice
    .venv/bin/python tools/under_load.py --burners 4 --rounds 3
    .venv/bin/python tools/under_load.py -- -k leader    # more pytest arguments after --

Starts --burners processes that spin a core each (pure Python arithmetic, at the normal priority
a test's neighbours have), then runs `pytest -m emulated_hardware` (tests/test_real_arm.py,
test_leader.py, test_fake_arm.py, test_calibrate.py) --rounds times in a row beside them. Passes
only if every round passes. Prints one line per round and exits with the first failing round's
pytest status (0 when all passed). The burners end with it, whatever happens.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def burn() -> None:
    """One core's worth of work, until killed."""
    total = 0
    while True:
        total = (total * 31 + 7) % 1_000_003


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(
        prog="tools/under_load.py", description=__doc__.split("\n\n")[0],
        epilog="Arguments after -- go to pytest.")
    parser.add_argument("--burners", type=int, default=2, help="CPU-bound processes beside the tests (default 2)")
    parser.add_argument("--rounds", type=int, default=2, help="times the tests run in a row (default 2)")
    own, pytest_args = (argv[: argv.index("--")], argv[argv.index("--") + 1 :]) if "--" in argv else (argv, [])
    args = parser.parse_args(own)
    if args.burners < 0 or args.rounds < 1:
        parser.error("--burners must be 0 or more and --rounds 1 or more")
    burners = [multiprocessing.Process(target=burn, daemon=True) for _ in range(args.burners)]
    for burner in burners:
        burner.start()
    status = 0
    try:
        for round_number in range(1, args.rounds + 1):
            started = time.monotonic()
            command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-n", "0", "-m", "emulated_hardware",
                       *pytest_args]
            result = subprocess.run(command, cwd=ROOT, capture_output=True, text=True)
            summary = (result.stdout.strip().splitlines() or ["(no output)"])[-1]
            print(f"round {round_number} of {args.rounds}, {args.burners} burners on {os.cpu_count()} cores: "
                  f"{summary} ({time.monotonic() - started:.0f} s)", flush=True)
            if result.returncode != 0:
                print(result.stdout[-6000:], result.stderr[-2000:], sep="\n", flush=True)
                status = status or result.returncode
    finally:
        for burner in burners:
            burner.kill()
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
