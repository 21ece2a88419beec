"""A LeRobot v2.x dataset made v3.0 by LeRobot's own converter, run in the policy environment (which has
LeRobot): in place, the original kept beside it as `NAME_old`, as LeRobot's converter leaves it.

This project reads and writes v3.0 only; many of the Hub's SO-101 datasets are v2.1. Writing a second
converter would copy LeRobot's; running its own keeps the two the same.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

from so101.dataset.layout import INFO_PATH, DatasetError

CONVERTER = "lerobot.datasets.v30.convert_dataset_v21_to_v30"
OFFLINE = {"HF_HUB_OFFLINE": "1", "HF_DATASETS_OFFLINE": "1"}


def version_of(root: Path) -> str:
    """The dataset's codebase_version, as its info.json says; DatasetError in one line where there is none."""
    try:
        info = json.loads((root / INFO_PATH).read_text(encoding="utf-8"))
        return str(info["codebase_version"])
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise DatasetError(f"{root} has no readable {INFO_PATH} with a codebase_version ({error}): "
                           "give the folder of a LeRobot dataset") from None


def check_convertible(root: Path) -> None:
    """DatasetError in one line where `root` is not a v2.x dataset that LeRobot's converter can take in place."""
    version = version_of(root)
    if version.startswith("v3."):
        raise DatasetError(f"{root} is already a LeRobot {version} dataset: nothing to convert")
    if not version.startswith("v2."):
        raise DatasetError(f"{root} is a LeRobot {version} dataset: LeRobot's converter takes v2.1 (v2.0: convert "
                           "it to v2.1 with LeRobot 0.3 first)")
    kept, scratch = root.with_name(f"{root.name}_old"), root.with_name(f"{root.name}_v30")
    for path in (kept, scratch):
        if path.exists():  # LeRobot's converter would delete it, or put it in the dataset's place
            raise DatasetError(f"{path} exists, and LeRobot's converter would replace it: move it away first")


def convert_to_v30(root: Path, python: Path, log: Path) -> Path:
    """Converts the v2.x dataset at `root` in place with LeRobot's converter under `python`; returns where the
    original was kept. DatasetError in one line, with nothing changed, where it cannot."""
    root = root.expanduser().resolve()
    check_convertible(root)
    kept = root.with_name(f"{root.name}_old")
    command = [str(python), "-m", CONVERTER, f"--repo-id={root.name}", f"--root={root.parent}", "--push-to-hub=false"]
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "w", encoding="utf-8") as output:
        done = subprocess.run(command, stdout=output, stderr=subprocess.STDOUT, env={**os.environ, **OFFLINE},
                              stdin=subprocess.DEVNULL)
    if done.returncode != 0:
        lines = [line for line in log.read_text(encoding="utf-8", errors="replace").splitlines() if line.strip()]
        raise DatasetError(f"LeRobot's converter failed (exit code {done.returncode}): "
                           f"{lines[-1] if lines else 'no output'} (log: {log})")
    return kept
