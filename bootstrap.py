#!/usr/bin/env python3
"""Set up this project from nothing but Python 3.11 and pip, then run it.

    python3.11 bootstrap.py          # set up, then start the dataflow with its prompt (so101 teleop)
    python3.11 bootstrap.py test     # set up with test tools and the policy environment, then run the whole test suite
    python3.11 bootstrap.py setup    # set up only

Set-up is idempotent: a virtual environment in .venv, this project installed in it
(editable), and the SO-101 model fetched and verified into assets/SO101. `test` also makes the
policy environment (`so101 policy-env`: LeRobot and torch, once per machine, several GB), which
the tests of trained policies run in; where it cannot be made, it says why and those tests are
skipped, saying so (`test --no-policy-env` skips it on purpose). The suite runs in parallel, one
worker per core (at most four; tests/conftest.py keeps dora's tests apart and runs the real-time
ones alone): on 2 cores 16 to 21 minutes, against 25 1/2 one test at a time (`test -n 0`;
docs/tests.md).
Any further arguments go to the command that runs (so101 teleop or pytest).
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
BIN = VENV / ("Scripts" if os.name == "nt" else "bin")
PYTHON = BIN / ("python.exe" if os.name == "nt" else "python")
STAMP = VENV / "so101-installed.json"  # what the last successful pip install was for


def run(*command: str | Path) -> None:
    print("+", " ".join(str(part) for part in command), flush=True)
    subprocess.run([str(part) for part in command], check=True, cwd=ROOT)


def set_up(with_tests: bool) -> None:
    if sys.version_info[:2] != (3, 11):
        sys.exit(
            f"bootstrap.py needs Python 3.11 (found {sys.version.split()[0]}): pybullet 3.2.7 has wheels "
            "only up to 3.11 and dora-rs 1.1.0 only from 3.11. Run it as `python3.11 bootstrap.py`."
        )
    if not PYTHON.exists():
        print(f"creating virtual environment {VENV}", flush=True)
        venv.EnvBuilder(with_pip=True).create(VENV)
    # pip is run again only when pyproject.toml changed or test tools are newly wanted:
    # a second run stays instant and works offline.
    wanted = {"pyproject_sha256": hashlib.sha256((ROOT / "pyproject.toml").read_bytes()).hexdigest(),
              "with_tests": with_tests}
    installed = _read_stamp()
    if not (installed.get("pyproject_sha256") == wanted["pyproject_sha256"]
            and (installed.get("with_tests") or not with_tests)):
        extras = "[test]" if with_tests else ""
        run(PYTHON, "-m", "pip", "install", "--quiet", "--disable-pip-version-check", "-e", f".{extras}")
        STAMP.write_text(json.dumps(wanted))
    run(BIN / "so101", "assets")


def _read_stamp() -> dict:
    try:
        stamp = json.loads(STAMP.read_text())
    except (OSError, ValueError):
        return {}
    return stamp if isinstance(stamp, dict) else {}


def main(argv: list[str]) -> int:
    if argv[:1] in (["-h"], ["--help"]):
        print(__doc__)
        return 0
    action, rest = (argv[0], argv[1:]) if argv and argv[0] in ("run", "test", "setup") else ("run", argv)
    try:
        set_up(with_tests=action == "test")
    except subprocess.CalledProcessError as error:
        print(f"set-up failed: {error}", file=sys.stderr)
        return error.returncode or 1
    # The venv's bin first on PATH: dora starts the nodes with the `python` it finds there.
    env = dict(os.environ, PATH=f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}", VIRTUAL_ENV=str(VENV))
    if action == "setup":
        print(f"ready. Activate with: source {VENV.relative_to(ROOT)}/bin/activate")
        return 0
    if action == "test":
        if "--no-policy-env" in rest:
            rest = [arg for arg in rest if arg != "--no-policy-env"]
        else:
            print("+", BIN / "so101", "policy-env", flush=True)
            if subprocess.call([str(BIN / "so101"), "policy-env"], cwd=ROOT, env=env) != 0:
                print("the policy environment could not be made (above): the tests that run a trained policy "
                      "will be skipped", flush=True)
        command = [str(PYTHON), "-m", "pytest", "-n", "auto", *rest]  # a later -n in `rest` wins
    else:
        command = [str(BIN / "so101"), "teleop", *rest]
    print("+", " ".join(command), flush=True)
    code = subprocess.call(command, cwd=ROOT, env=env)
    if action == "test" and code == 5:
        print("pytest collected no tests: that is a failure here", file=sys.stderr)
        return 1
    return code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
