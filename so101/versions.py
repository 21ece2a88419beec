"""The dora CLI and the dora-rs node library must be the same version.

Mixed versions (a `dora` from another install earlier on PATH, say) fail deep in
the daemon with errors that do not name the cause; this says it in one line.
"""

from __future__ import annotations

import importlib.metadata
import re
import shutil
import subprocess

LIBRARY_DISTRIBUTION = "dora-rs"
CLI_DISTRIBUTION = "dora-rs-cli"

_VERSION = re.compile(r"\bv?(\d+(?:\.\d+)*(?:[-.+]?[0-9A-Za-z.]+)?)\s*$")


def cli_version_from_output(output: str) -> str | None:
    """`dora --version` prints e.g. `dora-cli 1.1.0`: the version, or None if the text has none."""
    lines = output.strip().splitlines()
    match = _VERSION.search(lines[0].strip()) if lines else None
    return match.group(1) if match else None


def version_mismatch(cli_version: str, library_version: str, cli_path: str = "dora") -> str | None:
    """A one-line message naming both versions when they differ, else None."""
    if cli_version.strip() == library_version.strip():
        return None
    return (
        f"the dora CLI ({cli_path}) is version {cli_version} but the dora-rs library is version "
        f"{library_version}; they must match: pip install '{CLI_DISTRIBUTION}=={library_version}' "
        f"(or put the matching `dora` first on PATH)"
    )


def library_version() -> str | None:
    try:
        return importlib.metadata.version(LIBRARY_DISTRIBUTION)
    except importlib.metadata.PackageNotFoundError:
        return None


def cli_version(dora_executable: str) -> str | None:
    """What `dora --version` reports, or None if it does not run or prints no version."""
    try:
        result = subprocess.run(
            [dora_executable, "--version"], capture_output=True, text=True, timeout=30,
        )
    except (OSError, subprocess.TimeoutExpired):
        return None
    return cli_version_from_output(result.stdout) if result.returncode == 0 else None


def dora_version_problem(dora_executable: str | None = None) -> str | None:
    """Check the `dora` on PATH (or the one given) against the installed library: a message, or None if they match."""
    dora_executable = dora_executable or shutil.which("dora")
    library = library_version()
    if library is None:
        return f"the dora-rs library is not installed: pip install '{LIBRARY_DISTRIBUTION}'"
    if dora_executable is None:
        return f"the dora CLI is not on PATH: pip install '{CLI_DISTRIBUTION}=={library}'"
    cli = cli_version(dora_executable)
    if cli is None:
        return (
            f"could not read the version of the dora CLI ({dora_executable} --version); "
            f"the dora-rs library is version {library}: pip install '{CLI_DISTRIBUTION}=={library}'"
        )
    return version_mismatch(cli, library, dora_executable)


def dora_version_mismatch(dora_executable: str | None = None) -> str | None:
    """Only a proven mismatch: both versions read and different (for hints after another error)."""
    dora_executable = dora_executable or shutil.which("dora")
    library = library_version()
    cli = cli_version(dora_executable) if dora_executable else None
    if library is None or cli is None:
        return None
    return version_mismatch(cli, library, dora_executable)
