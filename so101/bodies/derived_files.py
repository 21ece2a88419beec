"""Files derived from the model (PyBullet's collision hulls, the cameras' meshes): a folder beside
it whose manifest lists each file's SHA-256 under a first line naming what they were derived with
(`key`), written so that a reader sees the old set or the new one, never half of one."""

from __future__ import annotations

import hashlib
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def folder_problem(folder: Path, manifest_name: str, key: str, names: set[str], stale: str) -> str | None:
    """Why `folder` cannot be used: "missing" (no manifest, or it lacks one of `names` or a file),
    `stale` (derived with another key), "corrupt" (a file is not what was written); None when it can."""
    try:
        first, *entries = (folder / manifest_name).read_text().splitlines()
    except (OSError, UnicodeDecodeError, ValueError):
        return "missing"
    if first != f"# {key}":
        return stale
    listed = {name: digest for digest, _, name in (entry.partition("  ") for entry in entries)}
    if not names <= set(listed):
        return "missing"
    for name, digest in listed.items():
        if not (folder / name).is_file():
            return "missing"
        if _digest(folder / name) != digest:
            return "corrupt"
    return None


@contextmanager
def writing_folder(folder: Path, manifest_name: str, key: str) -> Iterator[Path]:
    """A staging folder inside `folder` to write the derived files into; when the block ends without
    an error, they move into `folder` and their manifest after them. OSError where it cannot be written."""
    folder.mkdir(exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=".staging-", dir=folder) as staging_dir:
        staging = Path(staging_dir)
        yield staging
        names = sorted(path.name for path in staging.iterdir())
        (staging / manifest_name).write_text(
            "\n".join([f"# {key}"] + [f"{_digest(staging / name)}  {name}" for name in names]) + "\n"
        )
        # The manifest last: a reader sees it only once every file it lists is in place.
        for name in names + [manifest_name]:
            os.replace(staging / name, folder / name)
