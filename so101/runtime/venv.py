"""This interpreter's environment (the project's .venv): its tools, and a PATH that finds them first."""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

BIN = Path(sys.executable).parent


def executable(name: str) -> str | None:
    """`name` (dora, uv) from this interpreter's bin folder, else from PATH; None if neither has it."""
    beside_python = BIN / name
    return str(beside_python) if beside_python.exists() else shutil.which(name)


def env_with_bin_first(base: dict[str, str] | None = None) -> dict[str, str]:
    """A copy of the environment with this bin folder first on PATH: `dora run` starts `.py`
    nodes with the `python` it finds there, and it must be this one."""
    env = dict(os.environ if base is None else base)
    env["PATH"] = f"{BIN}{os.pathsep}{env.get('PATH', '')}"
    return env


def dora_executable(beside_python: bool = True) -> str | None:
    """The dora CLI. With `beside_python`, the one installed beside this interpreter (pinned with the
    library) when there is one: what this project runs itself. Otherwise the first on PATH: what a
    person's shell runs. None when there is none."""
    return executable("dora") if beside_python else shutil.which("dora")
