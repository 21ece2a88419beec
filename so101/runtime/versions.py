"""The dora CLI and the dora-rs node library must be the same version.

Mixed versions (a `dora` from another install earlier on PATH, say) fail deep in
the daemon with errors that do not name the cause; this says it in one line.
"""

from __future__ import annotations

import importlib.metadata
import os
import re
import subprocess
from pathlib import Path

from so101.runtime.venv import dora_executable as find_dora

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
    dora_executable = dora_executable or find_dora(beside_python=False)
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
    dora_executable = dora_executable or find_dora(beside_python=False)
    library = library_version()
    cli = cli_version(dora_executable) if dora_executable else None
    if library is None or cli is None or dora_executable is None:
        return None
    return version_mismatch(cli, library, dora_executable)


# -- the daemon a node runs under (Linux: read from /proc) -----------------------------------------
# dora 1.1 accepts any 1.x daemon next to any other, and a node of one 1.x version under a daemon
# of another, without a word (a 1.0.0 daemon joined a 1.1.0 coordinator and ran this project's
# 1.1.0 nodes). This project pins one version; a node checks the daemon it runs under.

DAEMON_DEFAULT_LOCAL_PORT = 53291  # dora's default `--local-listen-port`, which a dynamic node joins through


def _dora_of_process(pid: int) -> str | None:
    """The `dora` program a process runs (`dora daemon ...`, `dora run ...`), or None if it runs
    none or cannot be read. A pip-installed `dora` is a Python script: it is in the arguments."""
    proc = Path(f"/proc/{pid}")
    try:
        args = [arg.decode(errors="replace") for arg in (proc / "cmdline").read_bytes().split(b"\0")[:2]]
        for arg in args:
            if os.path.basename(arg) == "dora":
                program = os.path.join(os.readlink(proc / "cwd"), arg)  # an absolute `arg` stays as it is
                # A bare `dora` found on PATH is the executable itself.
                return program if os.path.exists(program) else os.readlink(proc / "exe")
    except OSError:
        pass
    return None


def listening_process(port: int) -> int | None:
    """The process that listens on TCP `port` of this machine, or None."""
    sockets = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            rows = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for row in rows:
            fields = row.split()
            if fields[3] == "0A" and int(fields[1].rsplit(":", 1)[1], 16) == port:  # 0A: LISTEN
                sockets.add(f"socket:[{fields[9]}]")
    if not sockets:
        return None
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            if any(os.readlink(f"/proc/{pid}/fd/{fd}") in sockets for fd in os.listdir(f"/proc/{pid}/fd")):
                return int(pid)
        except OSError:
            continue
    return None


def daemon_version_problem(daemon_pid: int | None) -> str | None:
    """One line when the dora daemon with this pid runs another dora version than this node's
    dora-rs library; None when they match, or when it cannot be told (no daemon, not Linux)."""
    dora = _dora_of_process(daemon_pid) if daemon_pid else None
    daemon, library = (cli_version(dora) if dora else None), library_version()
    if daemon is None or library is None or daemon == library:
        return None
    return (f"the dora daemon this node runs under ({dora}) is version {daemon}, this node's dora-rs is {library}: "
            f"use one dora version on every machine (this project pins {library}: start the daemon with this "
            f"project's .venv/bin/dora, or pip install '{CLI_DISTRIBUTION}=={library}' where it runs)")


def spawning_daemon_version_problem() -> str | None:
    """For a node the daemon started: that daemon is its parent process."""
    return daemon_version_problem(os.getppid())


def joined_daemon_version_problem(daemon_port: int | None) -> str | None:
    """For a dynamic node: the daemon is the process listening on the local port it joins through."""
    return daemon_version_problem(listening_process(daemon_port or DAEMON_DEFAULT_LOCAL_PORT))
