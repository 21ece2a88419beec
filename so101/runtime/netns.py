"""Machines on one lab network, made on this computer: a network namespace a machine (its own addresses,
ports and firewall), each joined by a virtual cable to a bridge in a namespace of its own, the switch.
`so101 cluster-demo --sealed` runs the sealed cluster in it, and the tests run the docs' steps between
its machines (a rogue one too). Needs root and iproute2 (`ip`); a capture of what crosses the switch
is every frame on its ports.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import struct
import subprocess
import time
from pathlib import Path

LAB_PREFIX = "10.231.0"  # the lab network's /24: machine i gets .i+1
SWITCH = "switch"
BRIDGE = "lab"
CABLE = "lab0"  # each machine's end of its cable (names are per namespace)

# Every frame on every port of the switch, each after its length (4 bytes, little-endian), to a file
# (argv: file): what a tap on the lab network sees.
SNIFFER = """
import socket, struct, sys, time
tap = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.ntohs(3))
with open(sys.argv[1], "wb") as frames:
    while True:
        try:
            frame = tap.recv(65535)
            frames.write(struct.pack("<I", len(frame)) + frame)
            frames.flush()
        except OSError:
            time.sleep(0.05)
"""


def read_frames(frames_file: Path) -> list[bytes]:
    """The frames `Rig.capture` wrote (a last one cut short is left out)."""
    data, frames, at = frames_file.read_bytes(), [], 0
    while at + 4 <= len(data):
        (length,) = struct.unpack_from("<I", data, at)
        if at + 4 + length > len(data):
            break
        frames.append(data[at + 4:at + 4 + length])
        at += 4 + length
    return frames


def rig_problem() -> str | None:
    """None where namespaces can be made here; else why not, in one line."""
    if os.geteuid() != 0:
        return "making machines of this one (network namespaces) needs root: run it with sudo"
    missing = [tool for tool in ("ip", "iptables") if not shutil.which(tool)]
    if missing:
        return f"{' and '.join(missing)} not found: `sudo apt-get install iproute2 iptables` (Debian, Ubuntu)"
    return None


def sh(*args: str, timeout_s: float = 30) -> str:
    return subprocess.run(args, check=True, capture_output=True, text=True, timeout=timeout_s).stdout


class Rig:
    """`machines` (names, in order: addresses LAB_PREFIX.1, .2, ...) on one switch."""

    def __init__(self, machines: list[str], tag: str | None = None):
        self.tag = tag or str(os.getpid())[-5:]
        self.ns = {name: f"so101-{name}-{self.tag}" for name in [*machines, SWITCH]}
        self.lab_address = {name: f"{LAB_PREFIX}.{index + 1}" for index, name in enumerate(machines)}
        self.machines = machines
        self.processes: list[subprocess.Popen] = []
        self.interfaces: list[str] = []

    def wire(self) -> None:
        for ns in self.ns.values():
            sh("ip", "netns", "add", ns)
        switch = self.ns[SWITCH]
        sh("ip", "-n", switch, "link", "add", BRIDGE, "type", "bridge")
        sh("ip", "-n", switch, "link", "set", BRIDGE, "up")
        for name in self.machines:
            ns, port = self.ns[name], f"port-{name}"[:15]
            sh("ip", "link", "add", CABLE, "netns", ns, "type", "veth", "peer", "name", port, "netns", switch)
            sh("ip", "-n", switch, "link", "set", port, "master", BRIDGE)
            sh("ip", "-n", switch, "link", "set", port, "up")
            sh("ip", "-n", ns, "addr", "add", f"{self.lab_address[name]}/24", "dev", CABLE)
            sh("ip", "-n", ns, "link", "set", "lo", "up")
            sh("ip", "-n", ns, "link", "set", CABLE, "up")

    def on(self, machine: str) -> list[str]:
        """The command prefix that runs a program on `machine`."""
        return ["ip", "netns", "exec", self.ns[machine]]

    def run(self, machine: str, args: list[str], **popen) -> subprocess.Popen:
        """A program left running on `machine`, in a session of its own (stopped by tear_down)."""
        process = subprocess.Popen([*self.on(machine), *args], start_new_session=True, **popen)
        self.processes.append(process)
        return process

    def capture(self, frames_file: Path, python: str) -> subprocess.Popen:
        """Every frame through the switch, to `frames_file`, until tear_down."""
        return self.run(SWITCH, [python, "-c", SNIFFER, str(frames_file)], stdin=subprocess.DEVNULL)

    def wireguard_up(self, machine: str, wireguard_file: Path, folder: Path) -> str:
        """`machine`'s WireGuard up (wg-quick) from its file, under an interface name of this rig's own:
        wireguard-go's control sockets are one folder for every namespace. Returns the interface."""
        interface = f"wg{self.tag}{machine}"[:15]
        copy = folder / f"{interface}.conf"
        shutil.copyfile(wireguard_file, copy)
        copy.chmod(0o600)
        self.interfaces.append(interface)
        sh(*self.on(machine), "wg-quick", "up", str(copy), timeout_s=60)
        return interface

    def cable_plugged(self, machine: str, plugged: bool) -> None:
        sh("ip", "-n", self.ns[machine], "link", "set", CABLE, "up" if plugged else "down")

    def listening(self, machine: str) -> list[tuple[str, str, str]]:
        """(protocol, local address:port, process) of every socket listening on `machine` (`ss`)."""
        found = []
        for line in sh(*self.on(machine), "ss", "-tlunpH").splitlines():
            fields = line.split()
            found.append((fields[0], fields[4], fields[6] if len(fields) > 6 else ""))
        return found

    def tear_down(self) -> None:
        """Every program the rig ran, and whatever still runs on its machines, stopped; the namespaces gone."""
        for process in self.processes:
            if process.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(process.pid, signal.SIGINT)
        deadline = time.monotonic() + 15
        for process in self.processes:
            with contextlib.suppress(subprocess.TimeoutExpired):
                process.wait(max(0.1, deadline - time.monotonic()))
        for ns in self.ns.values():
            pids = subprocess.run(["ip", "netns", "pids", ns], capture_output=True, text=True).stdout.split()
            for pid in pids:
                with contextlib.suppress(ProcessLookupError, ValueError):
                    os.kill(int(pid), signal.SIGKILL)
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)
        for interface in self.interfaces:  # wireguard-go killed above leaves its socket
            Path(f"/var/run/wireguard/{interface}.sock").unlink(missing_ok=True)

    def __enter__(self) -> "Rig":
        return self

    def __exit__(self, *exc) -> None:
        self.tear_down()
