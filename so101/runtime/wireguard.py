"""A sealed cluster: the dora cluster's machines joined by WireGuard, every dora listener on a tunnel address.

dora 1.1 encrypts nothing between machines (its coordinator speaks plain `ws://`, the token is a bearer
header, its Zenoh has no TLS), so `so101 cluster-dataflow --sealed` writes one WireGuard file a machine
(wg-quick's format; its own private key, the others' public keys) and says what to run on each: the
coordinator bound to the arm's tunnel address, each daemon's Zenoh listening on its own tunnel address
and dialling the others' (dora's `--zenoh-listen`/`--zenoh-connect`), no multicast scouting.

Each file also firewalls its tunnel address to its WireGuard interface (PostUp): Linux answers a
packet for any of its addresses on any interface, so without it a machine on the lab network that
routes the tunnel's addresses through the arm reaches the coordinator with no key at all (tried:
tests/test_sealed_cluster.py).

Plain functions (machines, addresses, files' text, command lines) and two edges: `wg` makes the
keys, and files are written never over one that exists.
"""

from __future__ import annotations

import ipaddress
import os
import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

TUNNEL_NETWORK = ipaddress.ip_network("10.101.0.0/24")
WIREGUARD_PORT = 51820  # UDP, on the machines that have an address: the only port the sealed cluster opens
COORDINATOR_PORT = 6013  # dora's default, on the arm's tunnel address
ZENOH_PORT = 7447  # each daemon's Zenoh, on its tunnel address
KEEPALIVE_S = 25  # from a machine with no address (a laptop behind NAT), so the others can answer it
INSTALL_HINT = ("WireGuard's tools are not installed: `sudo apt-get install wireguard-tools wireguard-go` (Debian, "
                "Ubuntu), or wireguard-tools with the kernel's WireGuard module")
# wg-quick names the interface after its file: so101-NAME, and Linux allows 15 characters.
MACHINE_ID = re.compile(r"[a-z0-9][a-z0-9_]{0,8}")
INTERFACE_PREFIX = "so101-"


class SealError(ValueError):
    """What is wrong with the machines asked for, or with writing their files: one line for the user."""


@dataclass(frozen=True)
class Machine:
    """One machine of the sealed cluster: its dora machine id, its address on the lab network (None:
    none the others can reach, e.g. a laptop), and its address inside the tunnel."""

    name: str
    lab_address: str | None
    tunnel_address: str

    @property
    def interface(self) -> str:
        return f"{INTERFACE_PREFIX}{self.name}"


def parse_machines(spec: str, coordinator_machine: str, required: tuple[str, ...]) -> list[Machine]:
    """`arm=192.168.1.10,desk[,gpu=192.168.1.30]` as machines, the coordinator's first (tunnel .1),
    the others in the order given. Every machine in `required` must be named; the coordinator's machine
    and, of any two machines, at least one need a lab address (WireGuard dials an address)."""
    named: dict[str, str | None] = {}
    for item in (part.strip() for part in spec.split(",")):
        name, has_address, address = item.partition("=")
        if not MACHINE_ID.fullmatch(name):
            raise SealError(f"{name!r} is not a machine id: 1 to 9 lower-case letters, digits or _, "
                            f"as in arm=192.168.1.10,desk")
        if name in named:
            raise SealError(f"machine {name!r} is named twice in {spec!r}")
        if has_address:
            try:
                address = str(ipaddress.ip_address(address))
            except ValueError:
                raise SealError(f"{address!r} (machine {name!r}) is not an IP address, e.g. {name}=192.168.1.10") from None
        named[name] = address if has_address else None
    missing = [name for name in required if name not in named]
    if missing:
        raise SealError(f"name the machine{'s' if len(missing) > 1 else ''} "
                        f"{' and '.join(missing)} (e.g. arm=192.168.1.10,desk), not {spec!r}")
    if named[coordinator_machine] is None:
        raise SealError(f"machine {coordinator_machine!r} runs the coordinator, so the others must reach it: give its "
                        f"address on the lab network, e.g. {coordinator_machine}=192.168.1.10")
    unreachable = [name for name, address in named.items() if address is None]
    if len(unreachable) > 1:
        raise SealError(f"machines {unreachable[0]!r} and {unreachable[1]!r} both have no address, so WireGuard cannot "
                        f"join them: give one its address (NAME=IP)")
    order = [coordinator_machine, *(name for name in named if name != coordinator_machine)]
    hosts = TUNNEL_NETWORK.hosts()
    return [Machine(name, named[name], str(next(hosts))) for name in order]


def wireguard_text(machine: Machine, private_key: str, peers: list[tuple[Machine, str]]) -> str:
    """wg-quick's file for `machine`: its key and tunnel address, the firewall that keeps its tunnel
    address to the tunnel, and each peer by public key (dialled where it has an address)."""
    lines = ["# so101 sealed cluster: machine " + repr(machine.name) + ". Secret: this machine's private key.",
             "# Up: sudo wg-quick up ./" + machine.interface + ".conf    Down: sudo wg-quick down ./" +
             machine.interface + ".conf",
             "[Interface]", f"PrivateKey = {private_key}", f"Address = {machine.tunnel_address}/{TUNNEL_NETWORK.prefixlen}"]
    if machine.lab_address is not None:
        lines.append(f"ListenPort = {WIREGUARD_PORT}")
    # Only what came through the tunnel, or from this machine itself, may reach the tunnel address
    # (Linux would answer on any interface).
    rule = f"INPUT -d {machine.tunnel_address}/32 ! -i %i -m addrtype ! --src-type LOCAL -j DROP"
    lines += [f"PostUp = iptables -I {rule}", f"PreDown = iptables -D {rule}"]
    for peer, public_key in peers:
        lines += ["", f"# machine {peer.name!r}", "[Peer]", f"PublicKey = {public_key}",
                  f"AllowedIPs = {peer.tunnel_address}/32"]
        if peer.lab_address is not None:
            lines.append(f"Endpoint = {endpoint(peer.lab_address, WIREGUARD_PORT)}")
            if machine.lab_address is None:
                lines.append(f"PersistentKeepalive = {KEEPALIVE_S}")
    return "\n".join(lines) + "\n"


def endpoint(address: str, port: int) -> str:
    return f"[{address}]:{port}" if ":" in address else f"{address}:{port}"


def coordinator_command(coordinator: Machine) -> list[str]:
    return ["dora", "coordinator", "--interface", coordinator.tunnel_address, "--port", str(COORDINATOR_PORT), "--auth"]


def daemon_command(machine: Machine, machines: list[Machine]) -> list[str]:
    """`machine`'s daemon: the coordinator through the tunnel, its Zenoh on its tunnel address only,
    dialling every other daemon (Zenoh 1.9+ peers relay nothing), no multicast scouting on the lab network."""
    command = ["dora", "daemon", "--machine-id", machine.name, "--coordinator-addr", machines[0].tunnel_address,
               "--coordinator-port", str(COORDINATOR_PORT), "--zenoh-listen", f"{machine.tunnel_address}:{ZENOH_PORT}"]
    for other in machines:
        if other != machine:
            command += ["--zenoh-connect", f"tcp/{other.tunnel_address}:{ZENOH_PORT}"]
    return [*command, "--zenoh-no-multicast"]


def missing_tools() -> str | None:
    """None where wg-quick, wg and a WireGuard (wireguard-go, or the kernel's) are here; else how to get them."""
    if not (shutil.which("wg") and shutil.which("wg-quick")):
        return INSTALL_HINT
    if not (shutil.which("wireguard-go") or Path("/sys/module/wireguard").exists()):
        return INSTALL_HINT
    return None


def new_key_pair() -> tuple[str, str]:
    """(private, public), made by `wg`."""
    private = subprocess.run(["wg", "genkey"], check=True, capture_output=True, text=True, timeout=10).stdout.strip()
    public = subprocess.run(["wg", "pubkey"], input=private, check=True, capture_output=True, text=True,
                            timeout=10).stdout.strip()
    return private, public


def write_wireguard_files(folder: Path, machines: list[Machine]) -> list[Path]:
    """One file a machine in `folder` (so101-NAME.conf, readable by its owner only), each with its own
    private key and no other; never over a file that exists (its keys may be in use)."""
    paths = [folder / f"{machine.interface}.conf" for machine in machines]
    existing = [path for path in paths if path.exists()]
    if existing:
        raise SealError(f"{existing[0]} exists: keys are never written over; remove it, or give another "
                        f"--wireguard-dir")
    if not shutil.which("wg"):
        raise SealError(INSTALL_HINT)
    keys = [new_key_pair() for _ in machines]
    folder.mkdir(parents=True, exist_ok=True)
    for index, (machine, path) in enumerate(zip(machines, paths)):
        peers = [(other, keys[other_index][1]) for other_index, other in enumerate(machines) if other_index != index]
        descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(descriptor, "w", encoding="utf-8") as file:
            file.write(wireguard_text(machine, keys[index][0], peers))
    return paths
