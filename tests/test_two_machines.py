"""The two-machine steps of docs/clusters.md, between two network namespaces that stand in for two machines:
each has an address and a firewall of its own, and a virtual cable joins them. The arm's machine
lets in only the coordinator's port and the Zenoh rendezvous; the laptop lets in nothing. A
capture on the laptop's end of the cable shows what travels in clear. The cable is pulled for a
while, as a network drops. Needs root, `ip` and `iptables` (.ci/run installs iptables).
"""

from __future__ import annotations

import itertools
import os
import re
import shutil
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest

from so101.runtime.processes import kill_with_env, running_with_env
from so101.runtime.venv import env_with_bin_first
from tests.helpers.dataflow import PROMPT_COMMAND, SO101

ARM_IP, DESK_IP = "10.231.0.1", "10.231.0.2"
COORDINATOR_PORT, ZENOH_PORT = 6013, 7447  # dora's default, and docs/clusters.md's rendezvous
CAN_SPLIT = os.geteuid() == 0 and shutil.which("ip") and shutil.which("iptables")

pytestmark = [
    pytest.mark.dataflow,
    pytest.mark.skipif(not CAN_SPLIT, reason="needs root, ip and iptables to make two machines of this one"),
]


# Every frame on the laptop's end of the cable, raw, to a file (argv: interface, file): what an
# eavesdropper on the network sees.
SNIFFER = """
import socket, sys, time
tap = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.ntohs(3))
tap.bind((sys.argv[1], 0))
with open(sys.argv[2], "wb") as frames:
    while True:
        try:
            frames.write(tap.recv(65535))
            frames.flush()
        except OSError:  # the cable pulled
            time.sleep(0.05)
"""


def sh(*args: str) -> str:
    return subprocess.run(args, check=True, capture_output=True, text=True, timeout=30).stdout


class TwoMachines:
    """Namespaces `arm` (ARM_IP) and `desk` (DESK_IP) joined by a veth pair, firewalled."""

    def __init__(self, tmp_path: Path):
        tag = str(os.getpid())[-5:]
        self.ns = {"arm": f"so101-arm-{tag}", "desk": f"so101-desk-{tag}"}
        self.cable = {"arm": f"s1a{tag}", "desk": f"s1d{tag}"}  # interface names: 15 characters at most
        self.tmp_path = tmp_path
        self.marker = f"{tmp_path}:{time.monotonic_ns()}"  # in every process started here, nodes included
        self.processes: list[subprocess.Popen] = []

    def wire(self) -> None:
        for machine in ("arm", "desk"):
            sh("ip", "netns", "add", self.ns[machine])
        sh("ip", "link", "add", self.cable["arm"], "type", "veth", "peer", "name", self.cable["desk"])
        for machine, address in (("arm", ARM_IP), ("desk", DESK_IP)):
            ns, cable = self.ns[machine], self.cable[machine]
            sh("ip", "link", "set", cable, "netns", ns)
            sh("ip", "-n", ns, "addr", "add", f"{address}/24", "dev", cable)
            sh("ip", "-n", ns, "link", "set", "lo", "up")
            sh("ip", "-n", ns, "link", "set", cable, "up")
            # Replies and loopback in; anything new from the other machine only where allowed below.
            self.iptables(machine, "-A", "INPUT", "-i", "lo", "-j", "ACCEPT")
            self.iptables(machine, "-A", "INPUT", "-m", "state", "--state", "ESTABLISHED,RELATED", "-j", "ACCEPT")
            self.iptables(machine, "-P", "INPUT", "DROP")
        for port in (COORDINATOR_PORT, ZENOH_PORT):
            self.iptables("arm", "-A", "INPUT", "-p", "tcp", "--dport", str(port), "-j", "ACCEPT")

    def iptables(self, machine: str, *rule: str) -> str:
        return sh("ip", "netns", "exec", self.ns[machine], "iptables", *rule)

    def cable_plugged(self, plugged: bool) -> None:
        sh("ip", "-n", self.ns["desk"], "link", "set", self.cable["desk"], "up" if plugged else "down")

    def env(self, machine: str, **extra: str) -> dict[str, str]:
        """A shell on a machine: this project's venv first on PATH, a home of its own, no dora settings but `extra`."""
        env = env_with_bin_first({name: value for name, value in os.environ.items() if not name.startswith("DORA_")})
        return dict(env, HOME=str(self.tmp_path / f"home-{machine}"), SO101_TWO_MACHINES=self.marker, **extra)

    def run(self, machine: str, args: list[str], name: str, stdin=None, **extra_env: str) -> subprocess.Popen:
        """A command left running on a machine; its output goes to NAME.log."""
        folder = self.tmp_path / machine
        folder.mkdir(exist_ok=True)
        with (self.tmp_path / f"{name}.log").open("w") as log:
            process = subprocess.Popen(["ip", "netns", "exec", self.ns[machine], *args], cwd=folder,
                                       env=self.env(machine, **extra_env), stdin=stdin, stdout=log,
                                       stderr=subprocess.STDOUT, text=True, start_new_session=True)
        self.processes.append(process)
        return process

    def dora(self, *args: str, token: str) -> subprocess.CompletedProcess:
        """The dora CLI on the laptop, pointed at the arm's coordinator."""
        return subprocess.run(["ip", "netns", "exec", self.ns["desk"], "dora", *args], capture_output=True, text=True,
                              env=self.env("desk", DORA_COORDINATOR_ADDR=ARM_IP, DORA_AUTH_TOKEN=token), timeout=60)

    def tear_down(self) -> None:
        for process in self.processes:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGINT)
        for process in self.processes:
            try:
                process.wait(15)
            except subprocess.TimeoutExpired:
                pass
        kill_with_env("SO101_TWO_MACHINES", self.marker, 15)
        for ns in self.ns.values():
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)

    def left_running(self) -> list[int]:
        return running_with_env("SO101_TWO_MACHINES", self.marker)


def replies(output: str) -> list[tuple[str, list[str]]]:
    """The prompt's transcript as (command, reply lines) in order."""
    blocks = []
    for line in output.splitlines():
        if line.startswith("> "):
            blocks.append((line[2:], []))
        elif blocks and line.strip():
            blocks[-1][1].append(line)
    return blocks


def first_angle(reply: str) -> float:
    return float(re.search(r"joint angles now: \[(-?[\d.]+),", reply).group(1))


SHORT_DROP_S, LONG_DROP_S = 5, 40  # within, and past, the coordinator's 30 s heartbeat watchdog
STALE = r"  no joint_state for \d+ s: the simulation \(or the arm's driver\), its machine or the network is gone; not sent"


def test_the_readme_steps_across_two_firewalled_machines_and_dropped_networks(tmp_path):
    """One session, two drops: a short one the dataflow rides out, then one past the watchdog that
    drops the laptop's daemon, after which `dora restart` and a new prompt drive the arm again."""
    machines = TwoMachines(tmp_path)
    try:
        machines.wire()
        captured = tmp_path / "frames.bin"
        machines.run("desk", [sys.executable, "-c", SNIFFER, machines.cable["desk"], str(captured)], "sniffer")
        # The arm's machine, terminals 1 and 2 (docs/clusters.md, "Across machines").
        machines.run("arm", ["dora", "coordinator", "--interface", ARM_IP, "--auth"], "coordinator")
        token_file = tmp_path / "home-arm" / ".config" / "dora" / ".dora-token"
        deadline = time.monotonic() + 30
        while not token_file.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        token = token_file.read_text().strip()
        zenoh = ["--zenoh-peer", f"tcp/{ARM_IP}:{ZENOH_PORT}"]
        machines.run("arm", ["dora", "daemon", "--machine-id", "arm", "--coordinator-addr", ARM_IP, *zenoh], "daemon-arm")
        time.sleep(1)
        # The laptop: its daemon with the token, the dataflow, then the prompt.
        machines.run("desk", ["dora", "daemon", "--machine-id", "desk", "--coordinator-addr", ARM_IP, *zenoh],
                     "daemon-desk", DORA_AUTH_TOKEN=token)
        deadline = time.monotonic() + 60
        while not all(f"{machine}-" in machines.dora("cluster", "status", token=token).stdout
                      for machine in ("arm", "desk")):
            assert time.monotonic() < deadline, "the daemons did not both join"
            time.sleep(0.5)
        dataflow = tmp_path / "placed_dataflow.yml"
        subprocess.run([str(SO101), "cluster-dataflow", "--mode", "direct", "--lang", "en", "-o", str(dataflow)],
                       check=True, capture_output=True, timeout=60)
        started = machines.dora("start", str(dataflow), "--name", "so101", "--detach", token=token)
        assert started.returncode == 0, started.stderr
        prompt_env = {"SO101_LANG": "en", "SO101_POSES_FILE": str(tmp_path / "poses.json")}
        prompt = machines.run("desk", PROMPT_COMMAND, "prompt", stdin=subprocess.PIPE, **prompt_env)

        def type_line(line: str, then_wait_s: float) -> None:
            prompt.stdin.write(line + "\n")
            prompt.stdin.flush()
            time.sleep(then_wait_s)

        logs = lambda: "".join(path.read_text() for path in (tmp_path / "arm").glob("_work/*/out/*/log_simulation.jsonl"))  # noqa: E731
        deadline = time.monotonic() + 60
        while "SO-101 loaded" not in logs():
            assert time.monotonic() < deadline, "the simulation did not start on the arm's machine"
            time.sleep(0.2)
        time.sleep(3)
        type_line("0 45", 3)
        type_line("state", 0.5)
        # Which connections crossed between the machines, and on which of the arm's ports.
        crossing = [line.split() for line in sh("ip", "netns", "exec", machines.ns["arm"], "ss", "-tnH").splitlines()
                    if DESK_IP in line]
        # The short drop: the cable out, a command refused; back in, `state` until the states come back.
        machines.cable_plugged(False)
        time.sleep(SHORT_DROP_S)
        type_line("0 -45", 0.5)
        machines.cable_plugged(True)
        deadline = time.monotonic() + 30
        while True:
            type_line("state", 1.0)
            last_reply = replies((tmp_path / "prompt.log").read_text())[-1][1]
            if last_reply and not re.fullmatch(STALE, last_reply[0]) or time.monotonic() > deadline:
                break
        watchdog_by_then = "Disconnecting daemons that failed watchdog" in (tmp_path / "coordinator.log").read_text(errors="replace")
        # The long drop: past the watchdog the laptop's daemon is dropped, and no state comes back.
        machines.cable_plugged(False)
        time.sleep(LONG_DROP_S)
        type_line("0 -45", 0.5)
        machines.cable_plugged(True)
        time.sleep(15)
        type_line("state", 0.5)
        type_line("quit", 2)
        prompt.wait(30)
        restarted = machines.dora("restart", "so101", token=token)
        assert restarted.returncode == 0, restarted.stderr
        prompt = machines.run("desk", PROMPT_COMMAND, "prompt-again", stdin=subprocess.PIPE, **prompt_env)
        time.sleep(10)
        type_line("0 -45", 4)
        type_line("state", 0.5)
        type_line("quit", 2)
        assert prompt.wait(30) == 0
        arm_firewall = machines.iptables("arm", "-L", "INPUT", "-n", "-v", "-x")
        coordinator_log = (tmp_path / "coordinator.log").read_text(errors="replace")
    finally:
        machines.tear_down()

    # Every connection between the machines ends at the arm's coordinator port or its Zenoh rendezvous.
    assert crossing and {int(fields[3].rsplit(":", 1)[1]) for fields in crossing} <= {COORDINATOR_PORT, ZENOH_PORT}
    for port in (COORDINATOR_PORT, ZENOH_PORT):
        assert re.search(rf"^\s*[1-9]\d*\s+\d+\s+ACCEPT\s.*dpt:{port}$", arm_firewall, re.M), arm_firewall
    first = replies((tmp_path / "prompt.log").read_text())
    assert first[0] == ("0 45", ["  → joint 0 (shoulder_pan) → 45°"])
    assert abs(first_angle(first[1][1][0]) - 45) <= 1.0
    # The short drop: the cable out, said and not sent; back in, states again and the arm held.
    assert first[2][0] == "0 -45" and re.fullmatch(STALE, first[2][1][0])
    polled = list(itertools.takewhile(lambda block: block[0] == "state", first[3:]))
    assert abs(first_angle(polled[-1][1][0]) - 45) <= 1.0, polled
    assert not watchdog_by_then
    # The long drop: the same refusal, the watchdog dropped the laptop's daemon, and no state came back.
    after_polls = first[3 + len(polled):]
    assert after_polls[0][0] == "0 -45" and re.fullmatch(STALE, after_polls[0][1][0])
    assert after_polls[1][0] == "state" and re.fullmatch(STALE, after_polls[1][1][0])
    assert "Disconnecting daemons that failed watchdog" in coordinator_log
    # Restarted, a new prompt drives the arm.
    last = replies((tmp_path / "prompt-again.log").read_text())
    assert last[0] == ("0 -45", ["  → joint 0 (shoulder_pan) → -45°"])
    assert abs(first_angle(last[1][1][0]) - (-45)) <= 1.0
    assert machines.left_running() == []
    # Nothing between the machines is encrypted: the token, and the joint angles as float64.
    frames = captured.read_bytes()
    assert token.encode() in frames
    assert struct.pack("<d", 45.0) in frames and struct.pack("<d", -45.0) in frames
