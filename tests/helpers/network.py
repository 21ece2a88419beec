"""A parallel worker's own network (tests/conftest.py): a namespace with loopback only, so that each
worker's dataflows have dora's fixed port 53291 to themselves; and the way back to the machine's
network for the one thing that must reach outside (pip fetching another dora)."""

from __future__ import annotations

import ctypes
import os
import shutil
import subprocess
from typing import Callable

CLONE_NEWNET = 0x40000000  # <sched.h>
_host_network_fd: int | None = None  # the machine's network namespace, once this process has left it


def _libc() -> ctypes.CDLL:
    return ctypes.CDLL(None, use_errno=True)


def network_of_its_own() -> bool:
    """Move this process (its calling thread, which starts every test's processes) into a new network
    namespace with loopback up; False where it may not (not root, no `ip`)."""
    global _host_network_fd
    if os.geteuid() != 0 or shutil.which("ip") is None:
        return False
    host = os.open("/proc/self/ns/net", os.O_RDONLY)
    if _libc().unshare(CLONE_NEWNET) != 0:
        os.close(host)
        return False
    if subprocess.run(["ip", "link", "set", "lo", "up"], capture_output=True).returncode != 0:
        _libc().setns(host, CLONE_NEWNET)  # a namespace without loopback would serve no dataflow: back
        os.close(host)
        return False
    _host_network_fd = host
    return True


def on_the_machines_network() -> Callable[[], None] | None:
    """A subprocess's preexec_fn that puts it back on the machine's network; None where this process never left it."""
    if _host_network_fd is None:
        return None
    fd = _host_network_fd

    def rejoin() -> None:
        if _libc().setns(fd, CLONE_NEWNET) != 0:
            raise OSError(ctypes.get_errno(), "setns to the machine's network failed")

    return rejoin
