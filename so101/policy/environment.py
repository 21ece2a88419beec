"""The policy environment: a virtual environment of its own with LeRobot, torch and dora-rs, whose
interpreter runs nodes/policy.py (`--policy-python`). LeRobot and torch are heavy, and LeRobot 0.5
and later need Python >= 3.12 while this project is 3.11, so they stay out of the project's .venv.
LeRobot's own `lerobot-eval` runs there too, on the Gymnasium environment (so101.gym), which it makes
in that interpreter: so the environment also holds the simulators and Gymnasium, and a `.pth` file
puts this checkout on its path (the project's plain modules, as the policy node reaches them).

`so101 policy-env` builds it once per machine (in the user's cache by default) and checks it: the
imports the node and lerobot-eval's environment make, offline. A built one is linked to the checkout
again (a moved checkout) and checked.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from so101.runtime.dataflow import ROOT
from so101.runtime.versions import LIBRARY_DISTRIBUTION, library_version

# LeRobot 0.4.4 is the last release for Python 3.11 (0.5 and later need 3.12); its pins take
# torch < 2.11. dora-rs is this project's own version: the daemon and the node library must match.
LEROBOT_REQUIREMENT = "lerobot==0.4.4"
DORA_REQUIREMENT = f"{LIBRARY_DISTRIBUTION}=={library_version()}"
# What so101.gym needs in lerobot-eval's interpreter: pyproject.toml's own pins (tests/test_gym.py holds them equal).
SIMULATION_REQUIREMENTS = ("pybullet==3.2.7", "mujoco>=4.0,<5", "gymnasium>=1.1.1,<2")
REQUIREMENTS = (LEROBOT_REQUIREMENT, DORA_REQUIREMENT, *SIMULATION_REQUIREMENTS)
# The file in the environment's site-packages that puts this checkout on its path.
CHECKOUT_LINK_NAME = "so101-checkout.pth"
# The dora-rs a Python holds, from its metadata (importing nothing: quick, before a dataflow starts).
DORA_PROBE = f"""
from importlib.metadata import PackageNotFoundError, version
try:
    print(version({LIBRARY_DISTRIBUTION!r}))
except PackageNotFoundError:
    print()
"""
STAMP_NAME = "so101-policy-env.json"
# What nodes/policy.py imports, and what lerobot-eval imports of so101.gym (its config, the checkout's
# modules, both simulators), and the versions; run offline, as the node and lerobot-eval run.
CHECK_SCRIPT = """
import json
import dora, numpy, pyarrow, torch
import lerobot
from lerobot.configs.policies import PreTrainedConfig
from lerobot.policies.factory import get_policy_class, make_pre_post_processors
import gymnasium, mujoco, pybullet
import so101.gym.lerobot_config, so101.gym.cube_to_box
from importlib.metadata import version
print(json.dumps({"lerobot": version("lerobot"), "torch": torch.__version__, "dora-rs": version("dora-rs"),
                  "numpy": numpy.__version__, "pyarrow": pyarrow.__version__, "gymnasium": gymnasium.__version__,
                  "mujoco": mujoco.__version__, "pybullet": version("pybullet"), "so101": so101.__path__[0]}))
"""
# Where an interpreter keeps its packages.
SITE_PACKAGES_PROBE = "import sysconfig; print(sysconfig.get_paths()['purelib'])"
OFFLINE = {"HF_HUB_OFFLINE": "1", "HF_DATASETS_OFFLINE": "1", "TRANSFORMERS_OFFLINE": "1"}


class PolicyEnvError(Exception):
    """The policy environment cannot be built or does not work; str() is one line for the user."""


def default_dir() -> Path:
    """Once per machine: in the user's cache ($XDG_CACHE_HOME, else ~/.cache), named for its LeRobot."""
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return cache / "so101" / f"policy-env-{LEROBOT_REQUIREMENT.replace('==', '-')}"


def python_in(folder: Path) -> Path:
    return folder / ("Scripts/python.exe" if os.name == "nt" else "bin/python")


@dataclass(frozen=True)
class PolicyEnv:
    """A working policy environment: its interpreter and what it holds."""

    python: Path
    versions: dict[str, str]

    def line(self) -> str:
        held = ", ".join(f"{name} {self.versions[name]}" for name in ("lerobot", "torch", "dora-rs"))
        return f"{self.python} ({held})"


def dora_problem(python: Path, timeout_s: float = 60.0, or_policy_env: bool = True) -> str | None:
    """Why interpreter `python` cannot run a node of this project's dataflows, in one line naming the fix: no
    dora-rs, or another version than the daemon's (this environment's); None when it has that one.
    `or_policy_env`: the fix also names `so101 policy-env` (not where that command itself asks)."""
    wanted = library_version()
    if wanted is None:  # this environment has no dora-rs to compare with: `so101 teleop` says so itself
        return None
    try:
        done = subprocess.run([str(python), "-c", DORA_PROBE], capture_output=True, text=True, timeout=timeout_s)
    except (OSError, subprocess.TimeoutExpired) as error:
        return f"{python} could not be run: {error}"
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["no message"])[-1]
        return f"{python} could not say its dora-rs version ({last})"
    held = done.stdout.strip()
    fix = f"{python} -m pip install '{LIBRARY_DISTRIBUTION}=={wanted}'"
    if or_policy_env:
        fix += " (or make a policy environment with `so101 policy-env`)"
    if not held:
        return f"{python} has no dora-rs, which the policy node needs to join the dataflow: {fix}"
    if held != wanted:
        return f"{python} has dora-rs {held}, but the dataflow runs dora-rs {wanted} and they must match: {fix}"
    return None


def check(python: Path, timeout_s: float = 300.0) -> PolicyEnv:
    """The environment of interpreter `python`, if it has this project's dora-rs and imports what the policy
    node needs (offline); PolicyEnvError in one line otherwise."""
    if not python.exists():
        raise PolicyEnvError(f"{python} does not exist: make a policy environment with `so101 policy-env`")
    problem = dora_problem(python, or_policy_env=False)
    if problem:
        raise PolicyEnvError(problem)
    try:
        # From the interpreter's own folder, with this checkout first on its path: as the nodes run, each
        # from its own checkout, whichever one the environment's link names (link_checkout).
        done = subprocess.run([str(python), "-c", CHECK_SCRIPT], capture_output=True, text=True, timeout=timeout_s,
                              env={**os.environ, **OFFLINE, "PYTHONPATH": with_checkout(os.environ.get("PYTHONPATH"))},
                              cwd=python.parent)
    except (OSError, subprocess.TimeoutExpired) as error:
        raise PolicyEnvError(f"{python} could not be run: {error}") from None
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["no message"])[-1]
        raise PolicyEnvError(f"{python} cannot import what the policy node needs ({last}): "
                             "make a policy environment with `so101 policy-env`")
    try:
        versions = json.loads(done.stdout.strip().splitlines()[-1])
    except (ValueError, IndexError):
        raise PolicyEnvError(f"{python} did not say its versions: {done.stdout.strip()[:200]}") from None
    return PolicyEnv(python, versions)


def build(folder: Path, base_python: str = sys.executable, say: Callable[[str], None] = print) -> PolicyEnv:
    """The policy environment in `folder`: checked if it was built; else made with `base_python`'s venv
    and pip (downloads: torch's wheel and its libraries, several GB), then checked."""
    python = python_in(folder)
    stamp = folder / STAMP_NAME
    if stamp.exists() and python.exists():
        try:
            if json.loads(stamp.read_text()).get("requirements") == list(REQUIREMENTS):
                link_checkout(python, say)
                return check(python)
        except (OSError, ValueError):
            pass  # a stamp that cannot be read: build again over it
    if folder.exists() and any(folder.iterdir()) and not python.exists():
        raise PolicyEnvError(f"{folder} is a folder with files and no Python environment in it: "
                             "name an empty or new folder")
    steps = [[base_python, "-m", "venv", str(folder)],
             [str(python), "-m", "pip", "install", "--disable-pip-version-check", "--quiet", *REQUIREMENTS]]
    for command in steps:
        say("+ " + " ".join(command))
        try:
            done = subprocess.run(command, capture_output=True, text=True)
        except OSError as error:
            raise PolicyEnvError(f"{command[0]} could not be run: {error}") from None
        if done.returncode != 0:
            last = (done.stderr.strip().splitlines() or done.stdout.strip().splitlines() or ["no message"])[-1]
            raise PolicyEnvError(f"`{' '.join(command[:4])} ...` failed: {last}")
    link_checkout(python, say)
    env = check(python)
    stamp.write_text(json.dumps({"requirements": list(REQUIREMENTS), "versions": env.versions}, indent=2))
    return env


def with_checkout(python_path: str | None, root: Path = ROOT) -> str:
    """A PYTHONPATH with the checkout `root` first: the policy environment serves every checkout on the
    machine, and each runs its own code there."""
    return os.pathsep.join(filter(None, [str(root), python_path]))


def link_checkout(python: Path, say: Callable[[str], None] = print, root: Path = ROOT) -> Path:
    """A .pth file in `python`'s site-packages naming the checkout `root`, so that its interpreter imports
    this project's modules when nothing else says which (lerobot-eval run by hand:
    `--env.discover_packages_path=so101.gym`); so101's nodes and commands put their own checkout first
    (with_checkout). Rewritten where the checkout moved, in one line naming the one it named before.
    Returns the file."""
    try:
        done = subprocess.run([str(python), "-c", SITE_PACKAGES_PROBE], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired) as error:
        raise PolicyEnvError(f"{python} could not be run: {error}") from None
    if done.returncode != 0 or not done.stdout.strip():
        raise PolicyEnvError(f"{python} did not say where its packages are: {(done.stderr.strip().splitlines() or [''])[-1]}")
    link = Path(done.stdout.strip().splitlines()[-1]) / CHECKOUT_LINK_NAME
    wanted = f"{root}\n"
    before = link.read_text(encoding="utf-8").strip() if link.exists() else ""
    if before != str(root):
        elsewhere = f" (it named {before}; so101's commands there still run that checkout's code)" if before else ""
        say(f"+ {link}: {root}: lerobot-eval run by hand in this environment imports this checkout's so101{elsewhere}")
        link.write_text(wanted, encoding="utf-8")
    return link
