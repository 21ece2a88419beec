"""`so101 cluster-demo` and `so101 cluster-dataflow`: the course's dataflow on a dora cluster.

`cluster-demo` starts what two real machines would run, on this one (so101/runtime/cluster.py):
a coordinator with token authentication, a daemon `arm` and a daemon `desk`; starts the
dataflow with `dora start` and runs the prompt in this terminal, joined through the `desk`
daemon. Quitting the prompt stops the dataflow, the daemons and the coordinator; nothing is
left running.

`cluster-dataflow` writes the file `dora start` needs on two real machines: a body's dataflow
placed the same way, with node paths made absolute under the project's folder on the arm's machine.

`--sealed` seals the cluster in WireGuard (so101/runtime/wireguard.py): `cluster-dataflow --sealed
arm=IP,desk` also writes one WireGuard file a machine and prints what to run on each;
`cluster-demo --sealed` runs the same on this computer, its machines made of network namespaces
(so101/runtime/netns.py, as root) and joined by WireGuard only.
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
    BODY_MACHINE, DATAFLOW_NAME, PROMPT_MACHINE, Cluster, ClusterError, cluster_dataflow, one_line, placed_dataflow,
    sealed_rig,
)
from so101.runtime.netns import rig_problem
from so101.runtime.dataflow import PROMPT_NODE_FILE, ROOT, dataflow_text
from so101.runtime.venv import dora_executable, env_with_bin_first
from so101.runtime.versions import dora_version_problem
from so101.runtime.wireguard import (
    INSTALL_HINT, Machine, SealError, coordinator_command, daemon_command, missing_tools, parse_machines,
    write_wireguard_files,
)

TEXT = {
    "zh": {
        "coordinator": "协调器在 {addr}:{port},令牌认证已开启",
        "daemon": "守护进程 {machine!r} 已加入(本地端口 {port})",
        "starts": "仿真在守护进程 {body!r} 上启动;键盘控制通过守护进程 {prompt!r} 加入",
        "stopping": "停止数据流、守护进程和协调器...",
        "stopped": "集群已停止",
        "wrote": "已写入 {output}:用 `dora start {output} --name {name} --detach` 启动它",
        "sealed": "在 WireGuard 中封闭:{folder} 中每台机器一个文件,私钥只在它自己机器的文件里。每台机器上:",
        "sealed_demo": "两台机器由本机的网络命名空间构成({arm} 与 {desk}),之间只有 WireGuard",
        "copy": "把 {file} 拷到这台机器(仅此一台)",
        "token": "令牌:协调器写在机器 {arm!r} 的 ~/.config/dora/.dora-token;在这里 export DORA_AUTH_TOKEN=...",
        "then": "然后(任意一台、带令牌):",
        "machine": "机器 {name!r}({address},隧道 {tunnel}):",
        "no_address": "无地址",
        "prompt_on": "机器 {name!r}:",
    },
    "en": {
        "coordinator": "coordinator on {addr}:{port}, token authentication on",
        "daemon": "daemon {machine!r} joined (local port {port})",
        "starts": "the simulation starts on daemon {body!r}; the prompt joins through daemon {prompt!r}",
        "stopping": "stopping the dataflow, the daemons and the coordinator...",
        "stopped": "cluster stopped",
        "wrote": "wrote {output}: start it with `dora start {output} --name {name} --detach`",
        "sealed": "sealed in WireGuard: one file a machine in {folder}, each private key in its own machine's file only. "
                  "On each machine:",
        "sealed_demo": "two machines made of network namespaces on this computer ({arm} and {desk}), WireGuard only "
                       "between them",
        "copy": "copy {file} to this machine (and no other)",
        "token": "the token: the coordinator writes it on machine {arm!r}, to ~/.config/dora/.dora-token; "
                 "export DORA_AUTH_TOKEN=... here",
        "then": "then, on any of them with the token:",
        "machine": "machine {name!r} ({address}, tunnel {tunnel}):",
        "no_address": "no address",
        "prompt_on": "machine {name!r}:",
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
        parser.add_argument("--sealed", metavar="MACHINES", default=None,
                            help="seal the cluster in WireGuard: the machines and their lab addresses, the arm's first, "
                            "e.g. arm=192.168.1.10,desk (a machine with no address, such as a laptop, dials the others); "
                            "writes one WireGuard file a machine and prints what to run on each")
        parser.add_argument("--wireguard-dir", type=Path, metavar="FOLDER", default=Path("so101-wireguard"),
                            help="--sealed: where the WireGuard files go (default ./so101-wireguard); files there are "
                            "never written over")
    parser.add_argument(
        "--mode", choices=MODES, default=os.environ.get("SO101_MODE", "auto"),
        help="the simulation's window: gui, direct (headless) or auto (default $SO101_MODE, else auto)",
    )
    add_language_option(parser, "the prompt and the logs")
    if name == "cluster-demo":
        parser.add_argument("--sealed", action="store_true",
                            help="make the two machines of network namespaces on this computer (as root), joined by "
                            "WireGuard only, every dora listener on the tunnel")
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
    if args.sealed:
        problem = rig_problem() or missing_tools()
        if problem:
            print(f"so101 cluster-demo --sealed: {problem}", file=sys.stderr)
            return 2
    if notice:
        print(notice, flush=True)
    if args.keep is not None:
        args.keep.mkdir(parents=True, exist_ok=True)
        return _demo(args.keep.resolve(), mode, args.lang, args.sealed)
    with tempfile.TemporaryDirectory(prefix="so101-cluster-") as work_dir:
        return _demo(Path(work_dir), mode, args.lang, args.sealed)


def _demo(work_dir: Path, mode: str, lang: str, sealed: bool = False) -> int:
    text = TEXT[lang]
    say = lambda line: print(line, flush=True)  # noqa: E731
    previous = signal.getsignal(signal.SIGINT)
    rig = None
    cluster = None
    try:
        seal = None
        if sealed:
            rig, seal = sealed_rig(work_dir, [BODY_MACHINE, PROMPT_MACHINE])
            say(text["sealed_demo"].format(arm=rig.ns[BODY_MACHINE], desk=rig.ns[PROMPT_MACHINE]))
        cluster = Cluster(work_dir, seal=seal)
        say(text["coordinator"].format(addr=cluster.coordinator_addr, port=cluster.coordinator_port))
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
        on = rig.on(PROMPT_MACHINE) if rig else []
        prompt = subprocess.Popen([*on, sys.executable, str(PROMPT_NODE_FILE)], env=env)
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C at the terminal is the prompt's: it quits on it
        return prompt.wait()
    except (ClusterError, SealError) as error:
        print(f"so101 cluster-demo: {error}", file=sys.stderr)
        return 1
    except subprocess.CalledProcessError as error:  # the rig: `ip` or wg-quick refused
        said = one_line(error.stderr or "").splitlines() or [""]
        print(f"so101 cluster-demo: {' '.join(map(str, error.cmd))} failed: {said[0][-300:]}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not cut the clean-up short
        say(text["stopping"])
        if cluster is not None:
            cluster.stop()
        if rig is not None:
            rig.tear_down()
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
    machines: list[Machine] = []
    if args.sealed is not None:
        try:
            machines = parse_machines(args.sealed, BODY_MACHINE, (BODY_MACHINE, PROMPT_MACHINE))
        except SealError as error:
            print(f"so101 cluster-dataflow: --sealed: {error}", file=sys.stderr)
            return 2
        if args.output is None:
            print("so101 cluster-dataflow: --sealed writes files: give the dataflow's too, with -o FILE", file=sys.stderr)
            return 2
    text = dataflow_text(placed_dataflow(body, node_env, PurePosixPath(args.root)), body.dataflow_file.name)
    if args.output is None:
        sys.stdout.write(text)
        return 0
    if machines:
        try:
            files = write_wireguard_files(args.wireguard_dir, machines)
        except SealError as error:
            print(f"so101 cluster-dataflow: --sealed: {error}", file=sys.stderr)
            return 2
        if missing_tools():  # `wg` made the keys; wg-quick or WireGuard itself is missing, and each machine needs them
            print(f"so101 cluster-dataflow: note: {INSTALL_HINT} (on each machine)", flush=True)
    args.output.write_text(text, encoding="utf-8")
    print(TEXT[args.lang]["wrote"].format(output=args.output, name=DATAFLOW_NAME))
    if machines:
        print(sealed_steps(machines, files, args.output, args.lang))
    return 0


def sealed_steps(machines: list[Machine], files: list[Path], dataflow: Path, lang: str) -> str:
    """What to run on each machine of a sealed cluster, in order: WireGuard up, then dora."""
    text = TEXT[lang]
    lines = [text["sealed"].format(folder=files[0].parent)]
    for index, (machine, wireguard_file) in enumerate(zip(machines, files)):
        head = text["machine"].format(name=machine.name, address=machine.lab_address or text["no_address"],
                                      tunnel=machine.tunnel_address)
        lines += ["", f"  # {head} {text['copy'].format(file=wireguard_file.name)}",
                  f"  sudo wg-quick up ./{wireguard_file.name}"]
        if index == 0:
            lines.append("  " + " ".join(coordinator_command(machine)))
        else:
            lines.append("  # " + text["token"].format(arm=machines[0].name))
        lines.append("  " + " ".join(daemon_command(machine, machines)))
    lines += ["", "  # " + text["then"],
              f"  DORA_COORDINATOR_ADDR={machines[0].tunnel_address} dora start {dataflow} --name {DATAFLOW_NAME} --detach",
              f"  # {text['prompt_on'].format(name=PROMPT_MACHINE)} python nodes/keyboard_control.py"]
    return "\n".join(lines)
