"""The steps of docs/clusters.md between machines made of network namespaces on one switch
(so101/runtime/netns.py): each has an address, ports and a firewall of its own.

Open: the arm's machine lets in only the coordinator's port and the Zenoh rendezvous, and a tap on
the switch reads the token and the joint angles. Sealed: the machines run the lines that `so101
cluster-dataflow --sealed` prints, WireGuard in user space between them; a third machine with the
token but no key tries the coordinator, a daemon of its own and a raw Zenoh peer, the tap finds
nothing in clear, and the network drops (the tunnel taken down, then the cable pulled past the
coordinator's watchdog) are ridden out or recovered from. Needs root, `ip`, `iptables`, and for the
sealed cluster wireguard-go and wireguard-tools (.ci/run installs them).
"""

from __future__ import annotations

import ipaddress
import itertools
import json
import os
import re
import shlex
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest

from so101.runtime.netns import Rig, read_frames, rig_problem, sh
from so101.runtime.processes import kill_with_env, running_with_env
from so101.runtime.venv import env_with_bin_first
from so101.runtime.wireguard import WIREGUARD_PORT, missing_tools, parse_machines
from tests.helpers.dataflow import PROMPT_COMMAND, ROOT, SO101, prompt_env

ARM, DESK, ROGUE = "arm", "desk", "rogue"
COORDINATOR_PORT, ZENOH_PORT = 6013, 7447  # dora's default, and docs/clusters.md's rendezvous
ZENOH_PEER = ROOT / "tests" / "helpers" / "zenoh_peer.py"
CAN_SPLIT = rig_problem() is None

pytestmark = [
    pytest.mark.dataflow,
    pytest.mark.skipif(not CAN_SPLIT, reason=f"cannot make machines of this one: {rig_problem()}"),
]

# From a machine: a TCP connection to each ADDRESS:PORT (argv, comma separated), 3 s each; what came of it, as JSON.
CONNECT = """
import json, socket, sys
outcomes = {}
for target in sys.argv[1].split(","):
    address, port = target.rsplit(":", 1)
    try:
        socket.create_connection((address, int(port)), timeout=3).close()
        outcomes[target] = "connected"
    except socket.timeout:
        outcomes[target] = "timed out"
    except OSError as error:
        outcomes[target] = error.strerror
print(json.dumps(outcomes))
"""


class Lab:
    """The rig's machines as a person uses them: a terminal each (a home of its own, this project's venv
    first on PATH, no dora settings), every program's output in NAME.log."""

    def __init__(self, tmp_path: Path, machines: list[str]):
        self.rig = Rig(machines)
        self.tmp_path = tmp_path
        self.marker = f"{tmp_path}:{time.monotonic_ns()}"  # in every process started here, nodes included

    def env(self, machine: str, **extra: str) -> dict[str, str]:
        env = env_with_bin_first({name: value for name, value in os.environ.items() if not name.startswith("DORA_")})
        return dict(env, HOME=str(self.tmp_path / f"home-{machine}"), SO101_TWO_MACHINES=self.marker, **extra)

    def run(self, machine: str, args: list[str], name: str, stdin=None, **extra_env: str) -> subprocess.Popen:
        folder = self.tmp_path / machine
        folder.mkdir(exist_ok=True)
        with (self.tmp_path / f"{name}.log").open("w") as log:
            return self.rig.run(machine, args, cwd=folder, env=self.env(machine, **extra_env), stdin=stdin,
                                stdout=log, stderr=subprocess.STDOUT, text=True)

    def log(self, name: str) -> str:
        return (self.tmp_path / f"{name}.log").read_text(errors="replace")

    def dora(self, machine: str, *args: str, token: str, coordinator: str, timeout_s: float = 60) -> subprocess.CompletedProcess:
        return subprocess.run([*self.rig.on(machine), "dora", *args], capture_output=True, text=True, timeout=timeout_s,
                              env=self.env(machine, DORA_COORDINATOR_ADDR=coordinator, DORA_AUTH_TOKEN=token))

    def token(self) -> str:
        """The token the coordinator on the arm's machine writes under its home."""
        token_file = self.tmp_path / f"home-{ARM}" / ".config" / "dora" / ".dora-token"
        deadline = time.monotonic() + 30
        while not token_file.exists():
            assert time.monotonic() < deadline, "the coordinator wrote no token"
            time.sleep(0.1)
        return token_file.read_text().strip()

    def wait_for_daemons(self, token: str, coordinator: str, machines=(ARM, DESK)) -> None:
        deadline = time.monotonic() + 60
        while not all(f"{machine}-" in self.dora(DESK, "cluster", "status", token=token, coordinator=coordinator).stdout
                      for machine in machines):
            assert time.monotonic() < deadline, f"the daemons did not all join: {self.log('daemon-desk')[-500:]}"
            time.sleep(0.5)

    def wait_for_simulation(self) -> None:
        deadline = time.monotonic() + 60
        while "SO-101 loaded" not in "".join(
                path.read_text() for path in (self.tmp_path / ARM).glob("_work/*/out/*/log_simulation.jsonl")):
            assert time.monotonic() < deadline, "the simulation did not start on the arm's machine"
            time.sleep(0.2)
        time.sleep(3)

    def prompt(self, name: str) -> "Prompt":
        env = {"SO101_LANG": "en", "SO101_POSES_FILE": str(self.tmp_path / "poses.json")}
        return Prompt(self.run(DESK, PROMPT_COMMAND, name, stdin=subprocess.PIPE, **env), self.tmp_path / f"{name}.log")

    def tear_down(self) -> None:
        self.rig.tear_down()
        kill_with_env("SO101_TWO_MACHINES", self.marker, 15)

    def left_running(self) -> list[int]:
        return running_with_env("SO101_TWO_MACHINES", self.marker)


class Prompt:
    def __init__(self, process: subprocess.Popen, log: Path):
        self.process, self.log = process, log

    def type(self, line: str, then_wait_s: float) -> None:
        self.process.stdin.write(line + "\n")
        self.process.stdin.flush()
        time.sleep(then_wait_s)

    def replies(self) -> list[tuple[str, list[str]]]:
        """The transcript as (command, reply lines) in order."""
        blocks: list[tuple[str, list[str]]] = []
        for line in self.log.read_text().splitlines():
            if line.startswith("> "):
                blocks.append((line[2:], []))
            elif blocks and line.strip():
                blocks[-1][1].append(line)
        return blocks

    def poll_state(self, timeout_s: float = 30) -> None:
        """`state` each second until an answer is the arm's, or `timeout_s`."""
        deadline = time.monotonic() + timeout_s
        while True:
            self.type("state", 1.0)
            last = self.replies()[-1][1]
            if last and not re.fullmatch(STALE, last[0]) or time.monotonic() > deadline:
                return


def first_angle(reply: list[str]) -> float:
    return float(re.search(r"joint angles now: \[(-?[\d.]+),", reply[0]).group(1))


LONG_DROP_S = 40  # past the coordinator's 30 s heartbeat watchdog
STALE = r"  no joint_state for \d+ s: the simulation \(or the arm's driver\), its machine or the network is gone; not sent"


def test_the_open_steps_across_firewalled_machines_and_what_a_tap_reads(tmp_path):
    lab = Lab(tmp_path, [ARM, DESK])
    arm_ip = lab.rig.lab_address[ARM]
    try:
        lab.rig.wire()
        for machine in (ARM, DESK):  # replies and loopback in; anything new only where allowed below
            iptables = [*lab.rig.on(machine), "iptables"]
            sh(*iptables, "-A", "INPUT", "-i", "lo", "-j", "ACCEPT")
            sh(*iptables, "-A", "INPUT", "-m", "state", "--state", "ESTABLISHED,RELATED", "-j", "ACCEPT")
            sh(*iptables, "-P", "INPUT", "DROP")
        for port in (COORDINATOR_PORT, ZENOH_PORT):
            sh(*lab.rig.on(ARM), "iptables", "-A", "INPUT", "-p", "tcp", "--dport", str(port), "-j", "ACCEPT")
        frames_file = tmp_path / "frames.bin"
        lab.rig.capture(frames_file, sys.executable)
        # The arm's machine, terminals 1 and 2; the laptop's daemon with the token (docs/clusters.md).
        lab.run(ARM, ["dora", "coordinator", "--interface", arm_ip, "--auth"], "coordinator")
        token = lab.token()
        zenoh = ["--zenoh-peer", f"tcp/{arm_ip}:{ZENOH_PORT}"]
        lab.run(ARM, ["dora", "daemon", "--machine-id", ARM, "--coordinator-addr", arm_ip, *zenoh], "daemon-arm")
        time.sleep(1)
        lab.run(DESK, ["dora", "daemon", "--machine-id", DESK, "--coordinator-addr", arm_ip, *zenoh], "daemon-desk",
                DORA_AUTH_TOKEN=token)
        lab.wait_for_daemons(token, arm_ip)
        dataflow = tmp_path / "placed_dataflow.yml"
        subprocess.run([str(SO101), "cluster-dataflow", "--mode", "direct", "--lang", "en", "-o", str(dataflow)],
                       check=True, capture_output=True, timeout=60)
        started = lab.dora(DESK, "start", str(dataflow), "--name", "so101", "--detach", token=token, coordinator=arm_ip)
        assert started.returncode == 0, started.stderr
        prompt = lab.prompt("prompt")
        lab.wait_for_simulation()
        prompt.type("0 45", 3)
        prompt.type("state", 0.5)
        prompt.type("0 -45", 3)
        prompt.type("state", 0.5)
        # Which connections crossed between the machines, and on which of the arm's ports.
        crossing = [line.split() for line in sh(*lab.rig.on(ARM), "ss", "-tnH").splitlines()
                    if lab.rig.lab_address[DESK] in line]
        prompt.type("quit", 2)
        assert prompt.process.wait(30) == 0
        arm_firewall = sh(*lab.rig.on(ARM), "iptables", "-L", "INPUT", "-n", "-v", "-x")
    finally:
        lab.tear_down()

    assert crossing and {int(fields[3].rsplit(":", 1)[1]) for fields in crossing} <= {COORDINATOR_PORT, ZENOH_PORT}
    for port in (COORDINATOR_PORT, ZENOH_PORT):
        assert re.search(rf"^\s*[1-9]\d*\s+\d+\s+ACCEPT\s.*dpt:{port}$", arm_firewall, re.M), arm_firewall
    said = prompt.replies()
    assert said[0] == ("0 45", ["  → joint 0 (shoulder_pan) → 45°"])
    assert abs(first_angle(said[1][1]) - 45) <= 1.0 and abs(first_angle(said[3][1]) + 45) <= 1.0
    assert lab.left_running() == []
    # Nothing between the machines is encrypted: the token, and the joint angles as float64.
    frames = b"".join(read_frames(frames_file))
    assert token.encode() in frames
    assert struct.pack("<d", 45.0) in frames and struct.pack("<d", -45.0) in frames


def printed_steps(output: str) -> dict[str, list[str]]:
    """What `so101 cluster-dataflow --sealed` prints to run, by machine ('then': on any of them)."""
    steps: dict[str, list[str]] = {}
    current = ""
    for line in (line.strip() for line in output.splitlines()):
        if line.startswith("# machine '") and "tunnel" in line:
            current = line.split("'")[1]
        elif line.startswith("# then"):
            current = "then"
        elif line and not line.startswith("#") and current:
            steps.setdefault(current, []).append(line)
    return steps


PROTOCOLS = {1: "icmp", 6: "tcp", 17: "udp"}


def between(frames: list[bytes], one: str, other: str) -> list[tuple[str, int, int]]:
    """(protocol, source port, destination port) of every IPv4 frame between two addresses; for an
    ICMP error, "icmp " and the protocol and ports of the packet it is about."""
    pair = {ipaddress.ip_address(one).packed, ipaddress.ip_address(other).packed}
    found = []
    for frame in frames:
        if frame[12:14] != b"\x08\x00" or {frame[26:30], frame[30:34]} != pair:
            continue
        packet, prefix = frame[14:], ""
        if packet[9] == 1 and packet[(packet[0] & 0x0F) * 4] == 3:  # destination unreachable: the packet it quotes
            packet, prefix = packet[(packet[0] & 0x0F) * 4 + 8:], "icmp "
        header = (packet[0] & 0x0F) * 4
        ports = struct.unpack_from("!HH", packet, header) if packet[9] in (6, 17) else (0, 0)
        found.append((prefix + PROTOCOLS.get(packet[9], str(packet[9])), *ports))
    return found


def readable_parts(frames: list[bytes]):
    """What a tap could read in each frame: a WireGuard data message's ciphertext without its header (whose
    counter's high zero bytes, followed by ciphertext, can look like a float64 such as 30.0), every other
    frame whole."""
    for frame in frames:
        if frame[12:14] == b"\x08\x00" and frame[23] == 17:
            udp = 14 + (frame[14] & 0x0F) * 4
            payload = frame[udp + 8:]
            if WIREGUARD_PORT in struct.unpack_from("!HH", frame, udp) and payload[:1] == b"\x04":
                yield payload[16:]
                continue
        yield frame


@pytest.mark.skipif(missing_tools() is not None, reason=f"no WireGuard here: {missing_tools()}")
def test_the_sealed_steps_keep_out_a_rogue_and_a_tap_and_ride_out_dropped_networks(tmp_path):
    lab = Lab(tmp_path, [ARM, DESK, ROGUE])
    arm_ip, desk_ip, rogue_ip = (lab.rig.lab_address[name] for name in (ARM, DESK, ROGUE))
    spec = f"{ARM}={arm_ip},{DESK}"
    tunnel = {machine.name: machine.tunnel_address for machine in parse_machines(spec, ARM, (ARM, DESK))}
    inside = f"tcp/{tunnel[ARM]}:{ZENOH_PORT},tcp/{tunnel[DESK]}:{ZENOH_PORT}"
    python = sys.executable
    try:
        lab.rig.wire()
        frames_file = tmp_path / "frames.bin"
        lab.rig.capture(frames_file, python)
        dataflow = tmp_path / "placed_dataflow.yml"
        written = subprocess.run([str(SO101), "cluster-dataflow", "--mode", "direct", "--lang", "en", "--sealed", spec,
                                  "--wireguard-dir", str(tmp_path / "wireguard"), "-o", str(dataflow)],
                                 check=True, capture_output=True, text=True, timeout=60)
        steps = printed_steps(written.stdout)
        # Each machine runs its lines as printed: WireGuard up (under an interface name of the rig's own), then dora.
        token = ""
        for machine in (ARM, DESK):
            for line in steps[machine]:
                if line.startswith("sudo wg-quick up ./"):
                    lab.rig.wireguard_up(machine, tmp_path / "wireguard" / line.rsplit("/", 1)[1], tmp_path)
                elif line.startswith("dora coordinator"):
                    lab.run(machine, shlex.split(line), "coordinator")
                    token = lab.token()
                else:
                    lab.run(machine, shlex.split(line), f"daemon-{machine}", DORA_AUTH_TOKEN=token)
        lab.wait_for_daemons(token, tunnel[ARM])
        assignment, *start = shlex.split(steps["then"][0])
        started = lab.dora(DESK, *start[1:], token=token, coordinator=assignment.split("=", 1)[1])
        assert started.returncode == 0, started.stderr
        prompt = lab.prompt("prompt")
        lab.wait_for_simulation()
        prompt.type("0 45", 3)
        prompt.type("state", 0.5)
        listening = {machine: lab.rig.listening(machine) for machine in (ARM, DESK)}

        # A raw Zenoh peer inside the tunnel (on the desk) keeps the command "0 30" as it crossed.
        capture = lab.run(DESK, [python, str(ZENOH_PEER), inside, "capture", str(tmp_path / "cmd.pickle"), "5"],
                          "zenoh-capture")
        while "open" not in lab.log("zenoh-capture"):
            assert capture.poll() is None, lab.log("zenoh-capture")
            time.sleep(0.1)
        time.sleep(1)
        prompt.type("0 30", 3)
        capture.wait(30)
        prompt.type("0 -30", 3)
        prompt.type("state", 0.5)

        # The rogue, on the same switch, holds the token (as if it saw it once) and routes the tunnel's
        # addresses through the arm's machine; it has no WireGuard key.
        sh(*lab.rig.on(ROGUE), "ip", "route", "add", str(ipaddress.ip_network(f"{tunnel[ARM]}/24", strict=False)),
           "via", arm_ip)
        everywhere = ",".join(f"tcp/{address}:{ZENOH_PORT}" for address in (arm_ip, desk_ip, tunnel[ARM], tunnel[DESK]))
        rogue = [
            lab.run(ROGUE, [python, "-c", CONNECT, ",".join(f"{address}:{port}" for address in (arm_ip, tunnel[ARM])
                                                           for port in (COORDINATOR_PORT, ZENOH_PORT))], "rogue-connect"),
            lab.run(ROGUE, [python, str(ZENOH_PEER), everywhere, "replay", str(tmp_path / "cmd.pickle"),
                            str(tmp_path / "rogue-heard.json"), "5"], "rogue-replay"),
        ]
        rogue_daemon = lab.run(ROGUE, ["dora", "daemon", "--machine-id", ROGUE, "--coordinator-addr", tunnel[ARM],
                                       "--zenoh-no-multicast"], "rogue-daemon", DORA_AUTH_TOKEN=token)
        rogue_cli_lab = lab.dora(ROGUE, "list", token=token, coordinator=arm_ip)
        rogue_cli_tunnel = lab.run(ROGUE, ["dora", "list"], "rogue-cli-tunnel", DORA_COORDINATOR_ADDR=tunnel[ARM],
                                   DORA_AUTH_TOKEN=token)
        for process in rogue:
            process.wait(60)
        cli_tunnel_answered = rogue_cli_tunnel.poll() is not None
        daemons_then = lab.dora(DESK, "cluster", "status", token=token, coordinator=tunnel[ARM]).stdout
        rogue_daemon_ran = rogue_daemon.poll() is None
        prompt.type("state", 0.5)
        # The same replay from inside the tunnel: what the rogue's would have done, had it reached a daemon.
        lab.run(DESK, [python, str(ZENOH_PEER), inside, "replay", str(tmp_path / "cmd.pickle"),
                       str(tmp_path / "desk-heard.json"), "2"], "desk-replay").wait(60)
        time.sleep(3)
        prompt.type("state", 0.5)
        arm_firewall = sh(*lab.rig.on(ARM), "iptables", "-L", "INPUT", "-n", "-v", "-x")

        # The tunnel dropped on the laptop for 5 s: said, not sent; back up, states again and the arm held.
        interface = lab.rig.interfaces[1]
        sh(*lab.rig.on(DESK), "wg-quick", "down", str(tmp_path / f"{interface}.conf"))
        time.sleep(5)
        prompt.type("0 -45", 0.5)
        sh(*lab.rig.on(DESK), "wg-quick", "up", str(tmp_path / f"{interface}.conf"))
        prompt.poll_state()
        after_tunnel = len(prompt.replies())
        # The laptop's cable out past the watchdog: the laptop's daemon is dropped, and no state comes back.
        lab.rig.cable_plugged(DESK, False)
        time.sleep(LONG_DROP_S)
        prompt.type("0 -45", 0.5)
        lab.rig.cable_plugged(DESK, True)
        time.sleep(10)
        prompt.type("state", 0.5)
        prompt.type("quit", 2)
        prompt.process.wait(30)
        restarted = lab.dora(DESK, "restart", "so101", token=token, coordinator=tunnel[ARM])
        assert restarted.returncode == 0, restarted.stderr
        again = lab.prompt("prompt-again")
        time.sleep(10)
        again.type("0 -45", 4)
        again.type("state", 0.5)
        again.type("quit", 2)
        assert again.process.wait(30) == 0
        coordinator_log = lab.log("coordinator")
    finally:
        lab.tear_down()

    # Every listener of dora's is on loopback or the machine's own tunnel address; only WireGuard faces the network.
    for machine in (ARM, DESK):
        for protocol, local, process in listening[machine]:
            if protocol == "udp":  # the arm's on the port its peers dial, the laptop's where the system put it
                assert "wireguard-go" in process and (machine == DESK or local.endswith(f":{WIREGUARD_PORT}")), listening
            else:
                assert local.rsplit(":", 1)[0] in ("127.0.0.1", tunnel[machine]), listening
    said = prompt.replies()
    assert said[0] == ("0 45", ["  → joint 0 (shoulder_pan) → 45°"]) and abs(first_angle(said[1][1]) - 45) <= 1.0
    assert said[4][0] == "state" and abs(first_angle(said[4][1]) + 30) <= 1.0
    # The rogue: refused on the lab address, nothing through the routed tunnel address, no daemon, no Zenoh.
    assert json.loads(lab.log("rogue-connect")) == {
        f"{arm_ip}:{COORDINATOR_PORT}": "Connection refused", f"{arm_ip}:{ZENOH_PORT}": "Connection refused",
        f"{tunnel[ARM]}:{COORDINATOR_PORT}": "timed out", f"{tunnel[ARM]}:{ZENOH_PORT}": "timed out"}
    assert rogue_cli_lab.returncode != 0 and "Connection refused" in rogue_cli_lab.stderr
    assert not cli_tunnel_answered  # it still waited for the coordinator when the rogue's other tries were done
    assert rogue_daemon_ran and f"{ROGUE}-" not in daemons_then and f"{DESK}-" in daemons_then
    assert json.loads((tmp_path / "rogue-heard.json").read_text()) == {}
    assert "replay done" in lab.log("rogue-replay")
    assert any(key.endswith("/simulation/joint_state") for key in json.loads((tmp_path / "desk-heard.json").read_text()))
    assert said[5][0] == "state" and abs(first_angle(said[5][1]) + 30) <= 1.0  # the rogue's replay moved nothing
    # Inside the tunnel the peer heard the arm's command and its replay moved the arm: dora's Zenoh trusts every peer.
    assert said[6][0] == "state" and abs(first_angle(said[6][1]) - 30) <= 1.0
    drops = re.search(rf"^\s*(\d+)\s+\d+\s+DROP\s.*{re.escape(tunnel[ARM])}\s.*ADDRTYPE", arm_firewall, re.M)
    assert drops and int(drops.group(1)) > 0, arm_firewall  # the firewall rule is what kept the routed tries out
    # The tunnel down: said, not sent; up again, the arm's states, the arm where it was.
    assert said[7][0] == "0 -45" and re.fullmatch(STALE, said[7][1][0])
    polled = list(itertools.takewhile(lambda block: block[0] == "state", said[8:after_tunnel]))
    assert abs(first_angle(polled[-1][1]) - 30) <= 1.0, polled
    # The long drop: refused, the watchdog dropped the laptop's daemon, no state came back; restarted, it drives.
    assert said[after_tunnel][0] == "0 -45" and re.fullmatch(STALE, said[after_tunnel][1][0])
    assert said[after_tunnel + 1][0] == "state" and re.fullmatch(STALE, said[after_tunnel + 1][1][0])
    assert "Disconnecting daemons that failed watchdog" in coordinator_log
    last = again.replies()
    assert last[0] == ("0 -45", ["  → joint 0 (shoulder_pan) → -45°"]) and abs(first_angle(last[1][1]) + 45) <= 1.0
    assert lab.left_running() == []
    # A tap on the switch: between the arm and the laptop, WireGuard's UDP and nothing else; no token, no angle,
    # no key expression in clear.
    frames = read_frames(frames_file)
    crossed = between(frames, arm_ip, desk_ip)
    # (While the laptop's WireGuard was down, it answered the arm's WireGuard packets "port unreachable".)
    assert len(crossed) > 1000 and all(protocol in ("udp", "icmp udp") and WIREGUARD_PORT in ports
                                       for protocol, *ports in crossed), set(crossed)
    tapped = list(readable_parts(frames))
    assert not any(token.encode() in part or b"dora/" in part or b"joint_cmd" in part for part in tapped)
    # The angles as they cross: float64, as the open test finds them in clear. (The four bytes of a float32
    # would turn up by chance in the run's ~40 MB of captured ciphertext about once in a hundred runs: no test.)
    for angle in (45.0, 30.0, -30.0, -45.0):
        assert not any(struct.pack("<d", angle) in part for part in tapped), angle
    assert between(frames, rogue_ip, arm_ip)  # the rogue's tries crossed the same switch


@pytest.mark.skipif(missing_tools() is not None, reason=f"no WireGuard here: {missing_tools()}")
def test_cluster_demo_sealed_drives_the_arm_across_two_namespaces_and_leaves_nothing(tmp_path):
    kept, log = tmp_path / "kept", tmp_path / "demo.log"
    with log.open("w") as output:
        demo = subprocess.Popen([str(SO101), "cluster-demo", "--sealed", "--mode", "direct", "--lang", "en", "--keep",
                                 str(kept)], stdin=subprocess.PIPE, stdout=output, stderr=subprocess.STDOUT, text=True,
                                env=prompt_env(tmp_path), start_new_session=True)
    tag = str(demo.pid)[-5:]  # the rig's: its namespaces' and WireGuard interfaces' names end with it
    try:
        deadline = time.monotonic() + 90
        while "SO-101 loaded" not in "".join(
                path.read_text() for path in kept.glob("daemon-arm/_work/*/out/*/log_simulation.jsonl")):
            assert demo.poll() is None and time.monotonic() < deadline, log.read_text()
            time.sleep(0.2)
        namespaces_then = sh("ip", "netns", "list")
        time.sleep(3)
        for line, wait_s in (("0 45", 3), ("state", 0.5), ("quit", 0)):
            demo.stdin.write(line + "\n")
            demo.stdin.flush()
            time.sleep(wait_s)
        assert demo.wait(60) == 0
    finally:
        if demo.poll() is None:
            os.killpg(demo.pid, signal.SIGINT)
            demo.wait(30)
    said = log.read_text()
    assert said.splitlines()[:2] == [
        f"two machines made of network namespaces on this computer (so101-arm-{tag} and so101-desk-{tag}), "
        "WireGuard only between them", "coordinator on 10.101.0.1:6013, token authentication on"]
    assert "  → joint 0 (shoulder_pan) → 45°" in said and re.search(r"joint angles now: \[4[45]\.\d+,", said)
    assert said.rstrip().endswith("cluster stopped")
    assert f"so101-arm-{tag}" in namespaces_then and f"-{tag}" not in sh("ip", "netns", "list")
    assert not list(Path("/var/run/wireguard").glob(f"wg{tag}*.sock"))
    for machine, address in ((ARM, "10.101.0.1"), (DESK, "10.101.0.2")):
        assert f"zenoh listener binding {address} (given via --zenoh-listen)" in (kept / f"daemon-{machine}.log").read_text()
