"""A dora cluster on this machine, and dataflows placed on a cluster's machines.

dataflow_cluster.yml places the simulation on the daemon with machine id `arm` and the
prompt on the one with machine id `desk` (dora 1.1's `deploy: machine:`). `Cluster` starts
what two real machines would run, on 127.0.0.1 with separate ports: a coordinator with token
authentication (`--auth`) and daemons (each in a working folder of its own, so each node's log
shows which daemon ran it); `so101 cluster-demo` (so101/cli/cluster.py) and the tests use it.
`placed_dataflow` writes a body's dataflow placed the same way, with node paths made absolute
under the project's folder on the arm's machine (dora 1.1 does not find a placed node by a
relative path).
"""

from __future__ import annotations

import os
import re
import socket
import subprocess
import time
from pathlib import Path, PurePath
from dataclasses import dataclass
from typing import IO, Callable, Protocol

from so101.runtime.dataflow import ROOT, dataflow_copy, write_dataflow
from so101.runtime.processes import kill_with_env, running_with_env, stop_process
from so101.runtime.venv import dora_executable, env_with_bin_first
from so101.runtime.netns import Rig
from so101.runtime.wireguard import (
    COORDINATOR_PORT, Machine, coordinator_command, daemon_command, parse_machines, write_wireguard_files,
)

CLUSTER_DATAFLOW = ROOT / "dataflow_cluster.yml"
DATAFLOW_NAME = "so101"
BODY_MACHINE, PROMPT_MACHINE = "arm", "desk"
START_TIMEOUT_S = 60.0
STOP_TIMEOUT_S = 15.0
RATE_LIMITED_S, RATE_LIMITED_RETRY_S = 120.0, 3.0


class PlacedBody(Protocol):
    """What placing a body needs to know of it (so101.bodies.registry.BodyKind has it)."""

    @property
    def dataflow_file(self) -> Path: ...

    @property
    def node_id(self) -> str: ...


class ClusterError(RuntimeError):
    """The cluster could not be brought up; str() is one line for the user."""


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def one_line(text: str) -> str:
    """dora's error output without its Rust backtrace and colour codes, as one line."""
    text = re.sub(r"\x1b\[[0-9;]*m", "", text).split("Location:")[0].split("Stack backtrace:")[0]
    return " ".join(line.strip() for line in text.splitlines() if line.strip() and line.strip() != "[ERROR]")


@dataclass(frozen=True)
class Seal:
    """A sealed cluster (so101.runtime.wireguard): its machines, the coordinator's first, their
    WireGuard up; how to run a program on one (`on(name)`, a command prefix: a machine of
    so101.runtime.netns's rig); and the machine inside the tunnel where the dora CLI runs."""

    machines: list[Machine]
    on: Callable[[str], list[str]]
    cli_machine: str

    def machine(self, name: str) -> Machine:
        return next(machine for machine in self.machines if machine.name == name)


def sealed_rig(work_dir: Path, machines: list[str]) -> tuple[Rig, Seal]:
    """`machines` made of network namespaces on this computer (so101.runtime.netns, as root), the first
    the coordinator's, each with its WireGuard up from the files `so101 cluster-dataflow --sealed`
    writes (in work_dir/wireguard). The second is the laptop of the docs' example: it has no address
    for the others to dial, and the dora CLI runs there. tear_down() the rig when done."""
    rig = Rig(machines)
    try:
        rig.wire()
        spec = ",".join(name if index == 1 else f"{name}={rig.lab_address[name]}" for index, name in enumerate(machines))
        sealed = parse_machines(spec, machines[0], tuple(machines))
        for machine, wireguard_file in zip(sealed, write_wireguard_files(work_dir / "wireguard", sealed)):
            rig.wireguard_up(machine.name, wireguard_file, work_dir)
    except BaseException:
        rig.tear_down()
        raise
    return rig, Seal(sealed, rig.on, machines[1])


class Cluster:
    """A coordinator (token authentication on) and daemons under `work_dir`: on 127.0.0.1 with
    ports of their own, or, `seal`ed, each on its machine with the sealed cluster's command lines."""

    def __init__(self, work_dir: Path, auth: bool = True, coordinator_addr: str = "127.0.0.1", seal: Seal | None = None):
        self.work_dir = work_dir
        self.seal = seal
        if seal is not None:
            coordinator_addr = seal.machines[0].tunnel_address
        self.coordinator_addr = coordinator_addr
        self.is_joined = False  # joined(): a cluster someone else runs
        # In the environment of every process the cluster starts, and so of every node its daemons
        # start: a node whose daemon was killed outlives it, and is found by this.
        self.marker = f"{work_dir.resolve()}:{os.getpid()}:{time.monotonic_ns()}"
        self.coordinator_port = COORDINATOR_PORT if seal else free_port()
        self.zenoh_port = free_port()
        self.auth = auth
        self.token: str | None = None
        self.processes: dict[str, subprocess.Popen] = {}
        self.daemon_ports: dict[str, int] = {}
        self._logs: list[IO[bytes]] = []

    # -- processes -----------------------------------------------------------------------

    def _spawn(self, name: str, args: list[str], env: dict[str, str], dora: str | None = None,
               machine: str | None = None) -> subprocess.Popen:
        folder = self.work_dir / name
        folder.mkdir(parents=True, exist_ok=True)
        log = (self.work_dir / f"{name}.log").open("wb")
        self._logs.append(log)
        # A session of its own, stopped as a whole; nodes that left it are found by the marker.
        on = self.seal.on(machine) if self.seal and machine else []
        process = subprocess.Popen([*on, dora or dora_executable() or "dora", *args], cwd=folder, stdin=subprocess.DEVNULL, stdout=log,
                                   stderr=subprocess.STDOUT, env=env, start_new_session=True)
        self.processes[name] = process
        return process

    def log(self, name: str) -> str:
        return (self.work_dir / f"{name}.log").read_text(errors="replace")

    def env(self, **extra: str) -> dict[str, str]:
        """The environment of a dora CLI or daemon of this cluster: its coordinator's port and token."""
        env = env_with_bin_first(dict(os.environ, DORA_COORDINATOR_ADDR=self.coordinator_addr,
                                      DORA_COORDINATOR_PORT=str(self.coordinator_port),
                                      SO101_CLUSTER_RUN=self.marker, **extra))
        if not self.is_joined:  # a cluster started here: its own token, or none
            env.pop("DORA_AUTH_TOKEN", None)
        if self.token:
            env["DORA_AUTH_TOKEN"] = self.token
        return env

    @classmethod
    def joined(cls, work_dir: Path, coordinator_addr: str, coordinator_port: int) -> "Cluster":
        """A cluster already running (its coordinator at the address, its token, if it asks for one,
        in DORA_AUTH_TOKEN): dataflows can be started on it; stop() stops nothing but those."""
        work_dir.mkdir(parents=True, exist_ok=True)
        cluster = cls(work_dir, auth=False, coordinator_addr=coordinator_addr)
        cluster.coordinator_port = coordinator_port
        cluster.is_joined = True
        return cluster

    def start_coordinator(self) -> None:
        home = self.work_dir / "home"  # `--auth` writes the token under $HOME: keep the user's own apart
        home.mkdir(parents=True, exist_ok=True)
        machine = None
        if self.seal:
            machine = self.seal.machines[0].name
            args = [*coordinator_command(self.seal.machines[0])[1:], "--store", "memory"]
        else:
            args = ["coordinator", "--interface", "127.0.0.1", "--port", str(self.coordinator_port), "--store", "memory",
                    *(["--auth"] if self.auth else [])]
        self._spawn("coordinator", args, dict(self.env(), HOME=str(home)), machine=machine)
        token_file = home / ".config" / "dora" / ".dora-token"
        deadline = time.monotonic() + START_TIMEOUT_S
        while "Listening on port" not in self.log("coordinator") or (self.auth and not token_file.exists()):
            if self.processes["coordinator"].poll() is not None or time.monotonic() > deadline:
                raise ClusterError(f"the coordinator did not start: {one_line(self.log('coordinator'))[-300:]}")
            time.sleep(0.1)
        if self.auth:
            self.token = token_file.read_text().strip()

    def start_daemon(self, machine_id: str, wait: bool = True, dora: str | None = None) -> subprocess.Popen:
        """A daemon under `machine_id`, run by this project's dora or another `dora` program."""
        if self.seal:  # a machine of its own: dora's default local port is free there
            self.daemon_ports[machine_id] = 53291
            args = daemon_command(self.seal.machine(machine_id), self.seal.machines)[1:]
        else:
            port = self.daemon_ports.setdefault(machine_id, free_port())
            args = ["daemon", "--machine-id", machine_id, "--coordinator-addr", "127.0.0.1",
                    "--coordinator-port", str(self.coordinator_port), "--local-listen-port", str(port),
                    # No multicast here (containers, CI): the daemons meet at one Zenoh endpoint.
                    "--zenoh-peer", f"tcp/127.0.0.1:{self.zenoh_port}"]
        process = self._spawn(f"daemon-{machine_id}", args, self.env(), dora, machine=machine_id)
        if wait:
            deadline = time.monotonic() + START_TIMEOUT_S
            while machine_id not in self.connected_daemons():
                if process.poll() is not None or time.monotonic() > deadline:
                    raise ClusterError(f"daemon {machine_id} did not join the coordinator: "
                                       f"{one_line(self.log(f'daemon-{machine_id}'))[-300:]}")
                time.sleep(0.2)
        return process

    def cli(self, *args: str, timeout_s: float = 60) -> subprocess.CompletedProcess:
        """The dora CLI against this cluster's coordinator. dora 1.1's coordinator answers a client that
        is not on loopback `429 Too Many Requests` after about 20 connections, for a while (seen: over
        a minute): such an answer is tried again, every RATE_LIMITED_RETRY_S, for up to RATE_LIMITED_S."""
        on = self.seal.on(self.seal.cli_machine) if self.seal else []
        deadline = time.monotonic() + RATE_LIMITED_S
        while True:
            done = subprocess.run([*on, dora_executable() or "dora", *args], capture_output=True, text=True,
                                  env=self.env(), timeout=timeout_s, cwd=self.work_dir)
            if "429 Too Many Requests" not in done.stderr or time.monotonic() > deadline:
                return done
            time.sleep(RATE_LIMITED_RETRY_S)

    def connected_daemons(self) -> list[str]:
        """The machine ids of the daemons the coordinator lists (`dora cluster status`)."""
        result = self.cli("cluster", "status", "--coordinator-addr", self.coordinator_addr,
                          "--coordinator-port", str(self.coordinator_port), timeout_s=20)
        ids = []
        for line in result.stdout.splitlines()[1:]:
            words = line.split()
            if words and not line.startswith("Active"):
                ids.append(words[0].rsplit("-", 5)[0])  # "arm-01a2072e-..." -> "arm"
        return ids

    def start_dataflow(self, dataflow: Path, name: str = DATAFLOW_NAME) -> None:
        result = self.cli("start", str(dataflow), "--name", name, "--detach")
        if result.returncode != 0:
            raise ClusterError(f"dora start failed: {one_line(result.stderr or result.stdout)}")

    def node_log(self, machine_id: str, node_id: str) -> str:
        """What a node logged, from the working folder of the daemon that ran it ('' if it did not)."""
        logs = sorted((self.work_dir / f"daemon-{machine_id}").glob(f"_work/*/out/*/log_{node_id}.jsonl"))
        return logs[-1].read_text(errors="replace") if logs else ""

    def wait_for_node_log(self, machine_id: str, node_id: str, marks, timeout_s: float = START_TIMEOUT_S) -> None:
        deadline = time.monotonic() + timeout_s
        while not any(mark in self.node_log(machine_id, node_id) for mark in marks):
            if time.monotonic() > deadline:
                raise ClusterError(f"{node_id} did not start on daemon {machine_id} within {timeout_s:g} s")
            time.sleep(0.2)

    def stop(self) -> None:
        """The dataflow, then every daemon, then the coordinator; anything left is killed. Safe twice."""
        if "coordinator" in self.processes and self.processes["coordinator"].poll() is None:
            try:
                self.cli("stop", "--name", DATAFLOW_NAME, timeout_s=STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                pass
        for name in sorted(self.processes, key=lambda name: name == "coordinator"):
            # Its session: the nodes a daemon spawned, if any outlived it.
            stop_process(self.processes[name], STOP_TIMEOUT_S, ask_session=True, kill_session=True)
        kill_with_env("SO101_CLUSTER_RUN", self.marker, STOP_TIMEOUT_S)
        for log in self._logs:
            log.close()
        self._logs.clear()

    def leftover_processes(self) -> list[int]:
        """The processes this cluster started that still run (its daemons' nodes included)."""
        return running_with_env("SO101_CLUSTER_RUN", self.marker)

    def __enter__(self) -> "Cluster":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def placed_dataflow(body: PlacedBody, node_env: dict[str, str], root: PurePath = ROOT) -> dict:
    """The body's dataflow (dataflow.yml for PyBullet) placed as dataflow_cluster.yml places it:
    the body's node on machine `arm`, the prompt on `desk`, with `node_env` over the body
    node's env. Node paths are made absolute under `root`, the project's folder on the arm's
    machine: once a node is placed, dora 1.1's `dora start` sends no working folder, and a
    daemon looks for a relative path in an empty folder of its own, where it is not found."""
    descriptor = dataflow_copy(node_env, body.dataflow_file, root)
    descriptor["nodes"] = [
        {"id": node["id"], "deploy": {"machine": BODY_MACHINE if node["id"] == body.node_id else PROMPT_MACHINE},
         **node}
        for node in descriptor["nodes"]
    ]
    return descriptor


def cluster_dataflow(work_dir: Path, node_env: dict[str, str], body: PlacedBody) -> Path:
    """`body`'s dataflow placed on daemons `arm` and `desk` of this machine, written under `work_dir`."""
    return write_dataflow(placed_dataflow(body, node_env), work_dir / "dataflow_cluster.yml")
