"""`so101 cluster-demo`: the course's dataflow on a dora cluster, two daemons on this machine.

dataflow_cluster.yml places the simulation on the daemon with machine id `arm` and the
prompt on the one with machine id `desk` (dora 1.1's `deploy: machine:`). This command starts
what two real machines would run, on 127.0.0.1 with separate ports: a coordinator with token
authentication (`--auth`), a daemon `arm` and a daemon `desk` (each in a working folder of
its own, so each node's log shows which daemon ran it), starts the dataflow with `dora start`,
and runs the prompt in this terminal, joined through the `desk` daemon. Quitting the prompt
stops the dataflow, the daemons and the coordinator; nothing is left running.

`so101 cluster-dataflow` writes the file `dora start` needs on two real machines: a body's
dataflow placed the same way, with node paths made absolute under the project's folder on the
arm's machine (dora 1.1 does not find a placed node by a relative path).

`Cluster` is the same set-up as a class, for the tests.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path, PurePath, PurePosixPath

from so101.bodies.registry import BODIES, DEFAULT_BODY, Body, body_node_env
from so101.runtime.dataflow import dataflow_copy, dataflow_text, write_dataflow
from so101.gui.display import MODES, resolve_mode
from so101.runtime.processes import kill_with_env, running_with_env
from so101.cli.course_steps import _language
from so101.runtime.venv import env_with_bin_first, executable
from so101.runtime.versions import dora_version_problem

ROOT = Path(__file__).resolve().parents[2]
CLUSTER_DATAFLOW = ROOT / "dataflow_cluster.yml"
PROMPT = ROOT / "nodes" / "keyboard_control.py"
DATAFLOW_NAME = "so101"
BODY_MACHINE, PROMPT_MACHINE = "arm", "desk"
START_TIMEOUT_S = 60.0
STOP_TIMEOUT_S = 15.0


class ClusterError(RuntimeError):
    """The cluster could not be brought up; str() is one line for the user."""


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _dora() -> str:
    return executable("dora") or "dora"


def _one_line(text: str) -> str:
    """dora's error output without its Rust backtrace and colour codes, as one line."""
    import re

    text = re.sub(r"\x1b\[[0-9;]*m", "", text).split("Location:")[0].split("Stack backtrace:")[0]
    return " ".join(line.strip() for line in text.splitlines() if line.strip() and line.strip() != "[ERROR]")


class Cluster:
    """A coordinator (token authentication on) and daemons, on 127.0.0.1, under `work_dir`."""

    def __init__(self, work_dir: Path, auth: bool = True):
        self.work_dir = work_dir
        # In the environment of every process the cluster starts, and so of every node its daemons
        # start: a node whose daemon was killed outlives it, and is found by this.
        self.marker = f"{work_dir.resolve()}:{os.getpid()}:{time.monotonic_ns()}"
        self.coordinator_port = free_port()
        self.zenoh_port = free_port()
        self.auth = auth
        self.token: str | None = None
        self.processes: dict[str, subprocess.Popen] = {}
        self.daemon_ports: dict[str, int] = {}
        self._logs = []

    # -- processes -----------------------------------------------------------------------

    def _spawn(self, name: str, args: list[str], env: dict[str, str], dora: str | None = None) -> subprocess.Popen:
        folder = self.work_dir / name
        folder.mkdir(parents=True, exist_ok=True)
        log = (self.work_dir / f"{name}.log").open("wb")
        self._logs.append(log)
        # A session of its own, stopped as a whole; nodes that left it are found by the marker.
        process = subprocess.Popen([dora or _dora(), *args], cwd=folder, stdin=subprocess.DEVNULL, stdout=log,
                                   stderr=subprocess.STDOUT, env=env, start_new_session=True)
        self.processes[name] = process
        return process

    def log(self, name: str) -> str:
        return (self.work_dir / f"{name}.log").read_text(errors="replace")

    def env(self, **extra: str) -> dict[str, str]:
        """The environment of a dora CLI or daemon of this cluster: its coordinator's port and token."""
        env = env_with_bin_first(dict(os.environ, DORA_COORDINATOR_PORT=str(self.coordinator_port),
                                      SO101_CLUSTER_RUN=self.marker, **extra))
        env.pop("DORA_AUTH_TOKEN", None)
        if self.token:
            env["DORA_AUTH_TOKEN"] = self.token
        return env

    def start_coordinator(self) -> None:
        home = self.work_dir / "home"  # `--auth` writes the token under $HOME: keep the user's own apart
        home.mkdir(parents=True, exist_ok=True)
        args = ["coordinator", "--interface", "127.0.0.1", "--port", str(self.coordinator_port), "--store", "memory"]
        self._spawn("coordinator", args + (["--auth"] if self.auth else []), dict(self.env(), HOME=str(home)))
        token_file = home / ".config" / "dora" / ".dora-token"
        deadline = time.monotonic() + START_TIMEOUT_S
        while "Listening on port" not in self.log("coordinator") or (self.auth and not token_file.exists()):
            if self.processes["coordinator"].poll() is not None or time.monotonic() > deadline:
                raise ClusterError(f"the coordinator did not start: {_one_line(self.log('coordinator'))[-300:]}")
            time.sleep(0.1)
        if self.auth:
            self.token = token_file.read_text().strip()

    def start_daemon(self, machine_id: str, wait: bool = True, dora: str | None = None) -> subprocess.Popen:
        """A daemon under `machine_id`, run by this project's dora or another `dora` program."""
        port = self.daemon_ports.setdefault(machine_id, free_port())
        args = ["daemon", "--machine-id", machine_id, "--coordinator-addr", "127.0.0.1",
                "--coordinator-port", str(self.coordinator_port), "--local-listen-port", str(port),
                # No multicast here (containers, CI): the daemons meet at one Zenoh endpoint.
                "--zenoh-peer", f"tcp/127.0.0.1:{self.zenoh_port}"]
        process = self._spawn(f"daemon-{machine_id}", args, self.env(), dora)
        if wait:
            deadline = time.monotonic() + START_TIMEOUT_S
            while machine_id not in self.connected_daemons():
                if process.poll() is not None or time.monotonic() > deadline:
                    raise ClusterError(f"daemon {machine_id} did not join the coordinator: "
                                       f"{_one_line(self.log(f'daemon-{machine_id}'))[-300:]}")
                time.sleep(0.2)
        return process

    def cli(self, *args: str, timeout_s: float = 60) -> subprocess.CompletedProcess:
        return subprocess.run([_dora(), *args], capture_output=True, text=True, env=self.env(), timeout=timeout_s,
                              cwd=self.work_dir)

    def connected_daemons(self) -> list[str]:
        """The machine ids of the daemons the coordinator lists (`dora cluster status`)."""
        result = self.cli("cluster", "status", "--coordinator-port", str(self.coordinator_port), timeout_s=20)
        ids = []
        for line in result.stdout.splitlines()[1:]:
            words = line.split()
            if words and not line.startswith("Active"):
                ids.append(words[0].rsplit("-", 5)[0])  # "arm-01a2072e-..." -> "arm"
        return ids

    def start_dataflow(self, dataflow: Path, name: str = DATAFLOW_NAME) -> None:
        result = self.cli("start", str(dataflow), "--name", name, "--detach")
        if result.returncode != 0:
            raise ClusterError(f"dora start failed: {_one_line(result.stderr or result.stdout)}")

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
            stop_session(self.processes[name])
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


def stop_session(process: subprocess.Popen) -> None:
    """Ctrl-C to a process started in a session of its own, then SIGKILL to whatever of the session is left."""
    if process.poll() is None:
        try:
            os.killpg(process.pid, signal.SIGINT)
            process.wait(STOP_TIMEOUT_S)
        except (ProcessLookupError, subprocess.TimeoutExpired):
            pass
    try:
        os.killpg(process.pid, signal.SIGKILL)  # nodes the daemon spawned, if any outlived it
    except (ProcessLookupError, PermissionError):
        pass
    process.wait()


def placed_dataflow(body: Body, node_env: dict[str, str], root: PurePath = ROOT) -> dict:
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


def cluster_dataflow(work_dir: Path, node_env: dict[str, str]) -> Path:
    """The PyBullet dataflow placed on daemons `arm` and `desk` of this machine, written under `work_dir`."""
    return write_dataflow(placed_dataflow(BODIES[DEFAULT_BODY], node_env), work_dir / "dataflow_cluster.yml")


# -- so101 cluster-demo, so101 cluster-dataflow ---------------------------------------------------

def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    if name == "cluster-dataflow":
        parser.add_argument(
            "--body", choices=list(BODIES), default=DEFAULT_BODY,
            help="what the arm's machine drives: pybullet (default), mujoco, or real (with --port and --calibration)",
        )
        parser.add_argument("--port", metavar="PORT", default=None,
                            help="--body real: the arm's serial port on the arm's machine (SO101_PORT)")
        parser.add_argument("--calibration", metavar="FILE", default=None,
                            help="--body real: the calibration JSON's absolute path on the arm's machine "
                            "(SO101_CALIBRATION)")
        parser.add_argument("--root", default=str(ROOT), metavar="FOLDER",
                            help=f"the project's folder on the arm's machine, an absolute path (default: this "
                            f"checkout's, {ROOT})")
        parser.add_argument("--output", "-o", type=Path, metavar="FILE", default=None,
                            help="write the dataflow to FILE (default: print it)")
    parser.add_argument(
        "--mode", choices=MODES, default=os.environ.get("SO101_MODE", "auto"),
        help="the simulation's window: gui, direct (headless) or auto (default $SO101_MODE, else auto)",
    )
    parser.add_argument(
        "--lang", type=_language, metavar="{zh,en}", default=os.environ.get("SO101_LANG", "zh"),
        help="language of the prompt and the logs (default: $SO101_LANG, else zh)",
    )
    if name == "cluster-demo":
        parser.add_argument("--keep", type=Path, metavar="FOLDER", default=None,
                            help="keep the coordinator's and daemons' logs and working folders in FOLDER (default: "
                            "a temporary folder, removed at exit)")


def run(args: argparse.Namespace) -> int:
    if args.command == "cluster-dataflow":
        return _write_placed_dataflow(args)
    try:
        mode, notice = resolve_mode(args.mode)
    except ValueError as error:
        print(f"so101 cluster-demo: {error} (from --mode or $SO101_MODE)", file=sys.stderr)
        return 2
    problem = dora_version_problem(_dora())
    if problem:
        print(f"so101 cluster-demo: {problem}", file=sys.stderr)
        return 2
    if notice:
        print(notice, flush=True)
    if args.keep is not None:
        args.keep.mkdir(parents=True, exist_ok=True)
        return _demo(args.keep.resolve(), mode, args.lang)
    with tempfile.TemporaryDirectory(prefix="so101-cluster-") as work_dir:
        return _demo(Path(work_dir), mode, args.lang)


def _demo(work_dir: Path, mode: str, lang: str) -> int:
    cluster = Cluster(work_dir)
    say = lambda line: print(line, flush=True)  # noqa: E731
    previous = signal.getsignal(signal.SIGINT)
    try:
        say(f"coordinator on 127.0.0.1:{cluster.coordinator_port}, token authentication on")
        cluster.start_coordinator()
        for machine_id in (BODY_MACHINE, PROMPT_MACHINE):
            cluster.start_daemon(machine_id)
            say(f"daemon {machine_id!r} joined (local port {cluster.daemon_ports[machine_id]})")
        cluster.start_dataflow(cluster_dataflow(work_dir, {"SO101_MODE": mode, "SO101_LANG": lang}))
        # The prompt joins at once: daemon `desk` runs no other node, and the dataflow starts once
        # every daemon's nodes are there (`state` says when the first joint_state has arrived).
        say(f"the simulation starts on daemon {BODY_MACHINE!r}; the prompt joins through daemon {PROMPT_MACHINE!r}")
        env = env_with_bin_first(dict(os.environ, SO101_LANG=lang,
                                      SO101_DAEMON_PORT=str(cluster.daemon_ports[PROMPT_MACHINE])))
        prompt = subprocess.Popen([sys.executable, str(PROMPT)], env=env)
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C at the terminal is the prompt's: it quits on it
        return prompt.wait()
    except ClusterError as error:
        print(f"so101 cluster-demo: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not cut the clean-up short
        say("stopping the dataflow, the daemons and the coordinator...")
        cluster.stop()
        signal.signal(signal.SIGINT, previous)
        say("cluster stopped")


def _write_placed_dataflow(args: argparse.Namespace) -> int:
    body = BODIES[args.body]
    # Paths on the arm's machine: taken as written, never resolved against this one's folders.
    for option, path in (("--root", args.root), ("--calibration", args.calibration)):
        if path is not None and not PurePosixPath(path).is_absolute():
            print(f"so101 cluster-dataflow: {option} must be an absolute path on the arm's machine, not {path!r}",
                  file=sys.stderr)
            return 2
    try:
        node_env = {"SO101_LANG": args.lang, **body_node_env(body, args.port, args.calibration)}
    except ValueError as error:
        print(f"so101 cluster-dataflow: {error}", file=sys.stderr)
        return 2
    if body.simulated:
        node_env["SO101_MODE"] = args.mode  # `auto` is settled by the node, on the arm's machine
    text = dataflow_text(placed_dataflow(body, node_env, PurePosixPath(args.root)), body.dataflow_file.name)
    if args.output is None:
        sys.stdout.write(text)
    else:
        args.output.write_text(text, encoding="utf-8")
        print(f"wrote {args.output}: start it with `dora start {args.output} --name {DATAFLOW_NAME} --detach`")
    return 0
