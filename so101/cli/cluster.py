"""`so101 cluster-demo` and `so101 cluster-dataflow`: the course's dataflow on a dora cluster.

`cluster-demo` starts what two real machines would run, on this one (so101/runtime/cluster.py):
a coordinator with token authentication, a daemon `arm` and a daemon `desk`; starts the
dataflow with `dora start` and runs the prompt in this terminal, joined through the `desk`
daemon. Quitting the prompt stops the dataflow, the daemons and the coordinator; nothing is
left running.

`cluster-dataflow` writes the file `dora start` needs on two real machines: a body's dataflow
placed the same way, with node paths made absolute under the project's folder on the arm's machine.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path, PurePosixPath

from so101.bodies.registry import BODIES, DEFAULT_BODY, body_node_env
from so101.runtime.argtypes import add_language_option
from so101.runtime.display import MODES, resolve_mode
from so101.runtime.cluster import (
    BODY_MACHINE, DATAFLOW_NAME, PROMPT_MACHINE, Cluster, ClusterError, cluster_dataflow, placed_dataflow,
)
from so101.runtime.dataflow import PROMPT_NODE_FILE, ROOT, dataflow_text
from so101.runtime.venv import dora_executable, env_with_bin_first
from so101.runtime.versions import dora_version_problem

TEXT = {
    "zh": {
        "coordinator": "协调器在 127.0.0.1:{port},令牌认证已开启",
        "daemon": "守护进程 {machine!r} 已加入(本地端口 {port})",
        "starts": "仿真在守护进程 {body!r} 上启动;键盘控制通过守护进程 {prompt!r} 加入",
        "stopping": "停止数据流、守护进程和协调器...",
        "stopped": "集群已停止",
        "wrote": "已写入 {output}:用 `dora start {output} --name {name} --detach` 启动它",
    },
    "en": {
        "coordinator": "coordinator on 127.0.0.1:{port}, token authentication on",
        "daemon": "daemon {machine!r} joined (local port {port})",
        "starts": "the simulation starts on daemon {body!r}; the prompt joins through daemon {prompt!r}",
        "stopping": "stopping the dataflow, the daemons and the coordinator...",
        "stopped": "cluster stopped",
        "wrote": "wrote {output}: start it with `dora start {output} --name {name} --detach`",
    },
}


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
    add_language_option(parser, "the prompt and the logs")
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
    problem = dora_version_problem(dora_executable())
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
    text = TEXT[lang]
    say = lambda line: print(line, flush=True)  # noqa: E731
    previous = signal.getsignal(signal.SIGINT)
    try:
        say(text["coordinator"].format(port=cluster.coordinator_port))
        cluster.start_coordinator()
        for machine_id in (BODY_MACHINE, PROMPT_MACHINE):
            cluster.start_daemon(machine_id)
            say(text["daemon"].format(machine=machine_id, port=cluster.daemon_ports[machine_id]))
        cluster.start_dataflow(cluster_dataflow(work_dir, {"SO101_MODE": mode, "SO101_LANG": lang}, BODIES[DEFAULT_BODY]))
        # The prompt joins at once: daemon `desk` runs no other node, and the dataflow starts once
        # every daemon's nodes are there (`state` says when the first joint_state has arrived).
        say(text["starts"].format(body=BODY_MACHINE, prompt=PROMPT_MACHINE))
        env = env_with_bin_first(dict(os.environ, SO101_LANG=lang,
                                      SO101_DAEMON_PORT=str(cluster.daemon_ports[PROMPT_MACHINE])))
        prompt = subprocess.Popen([sys.executable, str(PROMPT_NODE_FILE)], env=env)
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C at the terminal is the prompt's: it quits on it
        return prompt.wait()
    except ClusterError as error:
        print(f"so101 cluster-demo: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not cut the clean-up short
        say(text["stopping"])
        cluster.stop()
        signal.signal(signal.SIGINT, previous)
        say(text["stopped"])


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
        print(TEXT[args.lang]["wrote"].format(output=args.output, name=DATAFLOW_NAME))
    return 0
