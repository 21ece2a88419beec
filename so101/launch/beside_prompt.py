"""What the commands that run a dataflow beside the terminal share (so101 teleop, so101 replay).

Their options (the body, the task, the browser view, the log), the launch those options choose,
checked before anything starts, and `run_beside`: `dora run` in the background (so101.runtime.dora_run),
then a node in the foreground (the prompt, the replay) once the dataflow is ready, and the dataflow
stopped when that node ends, whatever ends it (quit, Ctrl-C, a closed terminal). On a cluster someone runs
(`so101 teleop --coordinator`: so101.launch.on_cluster), `dora start --attach` instead, every node on this
machine's daemon but the policy, where --policy-machine says, and the prompt joins through this machine's daemon.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from so101.bodies.registry import BODIES, DEFAULT_BODY, BodyKind, body_node_env
from so101.launch.on_cluster import ClusterPlace, joined_cluster, placed
from so101.runtime.argtypes import whole_number
from so101.runtime.cluster import ClusterError
from so101.runtime.dataflow import (
    LEADER_READY_MARKS, LOADED_MARKS, POLICY_NODE_ID, PROMPT_NODE_FILE, ROOT, with_web_view, write_dataflow,
)
from so101.runtime.display import MODES, resolve_mode
from so101.runtime.dora_run import Dataflow, log_tail, port_held_problem, refusal as refusal_in
from so101.runtime.dora_start import AttachedDataflow
from so101.runtime.processes import DAEMON_PORT_TAKEN_MARK
from so101.runtime.venv import dora_executable, env_with_bin_first
from so101.runtime.versions import dora_version_problem
from so101.tasks import TASKS, parse_seed, task_named
from so101.web.settings import (
    DEFAULT_HOST as DEFAULT_WEB_HOST, DEFAULT_PORT as DEFAULT_WEB_PORT, EVERY_ADDRESS, LOCAL_HOSTS, page_address,
)

DEFAULT_LOG = ROOT / "out" / "teleop-dora.log"
START_TIMEOUT_S = 90.0

TEXT = {
    "zh": {
        "starting": "启动数据流(dora run,{mode} 模式),日志写入 {log}",
        "starting_cluster": "在协调器 {coordinator} 的集群上启动数据流(dora start,{mode} 模式):机器 {here!r} 上运行身体和"
        "键盘控制{policy},日志写入 {log}",
        "policy_there": ",机器 {machine!r} 上运行策略",
        "ready": "仿真已就绪,启动键盘控制",
        "ready_real": "机械臂已就绪(已上扭矩),启动键盘控制",
        "ready_leader": "主臂已就绪:移动主臂,身体跟随",
        "stopping": "停止数据流...",
        "stopped": "数据流已停止",
        "exited": "dora run 提前退出(退出码 {code}),日志 {log} 最后几行:",
        "timeout": "{seconds:g} 秒内仿真未就绪,日志 {log} 最后几行:",
        "interrupted": "已中断",
        "port_held": "本机已有一个数据流在运行,占着键盘控制加入数据流的端口({port},dora 1.1 的 `dora run` 只用这一个):"
        "{holder};在这里启动的键盘控制会去驱动它。用那一个,或先停掉它(在它的终端按 Ctrl-C)再重新运行",
    },
    "en": {
        "starting": "starting the dataflow (dora run, {mode} mode), log in {log}",
        "starting_cluster": "starting the dataflow on the cluster of the coordinator at {coordinator} (dora start, "
        "{mode} mode): the body and the prompt on machine {here!r}{policy}, log in {log}",
        "policy_there": ", the policy on machine {machine!r}",
        "ready": "simulation ready, starting the keyboard prompt",
        "ready_real": "the arm is ready (torque on), starting the keyboard prompt",
        "ready_leader": "the leader is ready: move it and the body follows",
        "stopping": "stopping the dataflow...",
        "stopped": "dataflow stopped",
        "exited": "dora run exited early (exit code {code}); last lines of {log}:",
        "timeout": "the simulation was not ready within {seconds:g} s; last lines of {log}:",
        "interrupted": "interrupted",
        "port_held": "another dataflow runs on this machine and holds the port a prompt joins by ({port}, the only one "
        "dora 1.1's `dora run` takes): {holder}; a prompt started here would drive it. Use that one, or stop it "
        "(Ctrl-C in its terminal) and run this again",
    },
}


def _task_name(text: str) -> str:
    try:
        return task_named(text).name
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def _seed(text: str) -> int:
    try:
        return parse_seed(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def add_task_arguments(parser: argparse.ArgumentParser) -> None:
    """--task NAME, --seed N: a task's scene on a simulated body's floor."""
    parser.add_argument(
        "--task", type=_task_name, metavar="NAME", default=None,
        help=f"a task's scene on the floor ({', '.join(TASKS)}; --body pybullet or mujoco): the body publishes "
        "object_state and task_status; at the prompt: reset [SEED], task",
    )
    parser.add_argument("--seed", type=_seed, metavar="N", default=None,
                        help="--task: the first layout's seed, a whole number (default 0); `reset` goes on from it")


def add_web_arguments(parser: argparse.ArgumentParser) -> None:
    """--web, --web-port, --web-host: the arm in a browser too (teleop's and replay's)."""
    parser.add_argument(
        "--web", action="store_true",
        help="show the arm in a browser too (for a machine with no display): prints the page's address",
    )
    parser.add_argument("--web-port", type=whole_number(1, 65535), default=DEFAULT_WEB_PORT, metavar="P",
                        help=f"--web: the page's port (default {DEFAULT_WEB_PORT})")
    parser.add_argument("--web-host", default=DEFAULT_WEB_HOST, metavar="ADDRESS",
                        help=f"--web: the address to serve on (default {DEFAULT_WEB_HOST}, this machine only; "
                        "0.0.0.0 serves every network this machine is on)")


def add_web_view(args: argparse.Namespace, descriptor: dict, body: BodyKind, command: str) -> str:
    """With --web, the web view added to `descriptor` (and a warning printed when it serves beyond this
    machine); the line to print once it serves, or "" without --web."""
    if not args.web:
        return ""
    if args.web_host not in LOCAL_HOSTS:
        where = "every address of this machine" if args.web_host in EVERY_ADDRESS else args.web_host
        print(f"so101 {command}: the web view serves on {where}: anyone who can reach port {args.web_port} "
              "there sees the arm", flush=True)
    with_web_view(descriptor, body.node_id, {"SO101_WEB_HOST": args.web_host, "SO101_WEB_PORT": str(args.web_port)})
    return f"web view: {page_address(args.web_host, args.web_port)}"


def add_log_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--log", type=Path, default=DEFAULT_LOG, metavar="FILE",
        help=f"where the dataflow's log goes (default: {DEFAULT_LOG})",
    )


def add_body_arguments(parser: argparse.ArgumentParser) -> None:
    """--body, --port, --calibration, --mode: which body runs the dataflow, and how."""
    parser.add_argument(
        "--body", choices=list(BODIES), default=DEFAULT_BODY,
        help=f"what moves: pybullet (the course's simulation, default), mujoco, or real (an SO-101 follower arm, "
        f"with --port and --calibration); runs {', '.join(body.dataflow_file.name for body in BODIES.values())}",
    )
    parser.add_argument(
        "--port", metavar="PORT", default=None,
        help="--body real: the arm's serial port (/dev/ttyACM0, ...; `so101 fake-arm` prints an emulated one); "
        "passed to the arm node as SO101_PORT",
    )
    parser.add_argument(
        "--calibration", type=Path, metavar="FILE", default=None,
        help="--body real: the arm's calibration JSON (from `so101 calibrate`, or LeRobot's so101_follower one); "
        "passed to the arm node as SO101_CALIBRATION",
    )
    parser.add_argument(
        "--mode", choices=MODES, default=os.environ.get("SO101_MODE", "auto"),
        help="simulation window: gui, direct (headless) or auto (gui where a display exists; default $SO101_MODE, "
        "else auto); passed to the simulation as SO101_MODE",
    )


@dataclass(frozen=True)
class Launch:
    """What the options chose: the body, its display mode, its node's settings, the environment
    of `dora run` and the nodes it starts, and the log file."""

    body: BodyKind
    mode: str
    node_env: dict[str, str]
    env: dict[str, str]
    log: Path


def prepare(args: argparse.Namespace, command: str, node_file: Path = PROMPT_NODE_FILE) -> Launch | None:
    """The launch the options ask for (add_body_arguments', --lang's, --log's); None once one line
    on stderr said what is wrong."""
    body = BODIES[args.body]
    try:
        # A GUI without a display fails here, in one line. The real arm has no window to choose.
        resolved_mode, notice = resolve_mode(args.mode) if body.simulated else ("real", None)
    except ValueError as error:  # a bad $SO101_MODE: argparse does not check defaults against choices
        print(f"so101 {command}: {error} (from --mode or $SO101_MODE)", file=sys.stderr)
        return None
    if notice:
        print(notice, flush=True)
    if not body.dataflow_file.exists() or not node_file.exists():
        print(f"so101 {command}: {body.dataflow_file} or {node_file} is missing: run it from a checkout of the project",
              file=sys.stderr)
        return None
    # A CLI and library of different versions fail deep in the daemon; say it here, in one line.
    version_problem = dora_version_problem(dora_executable())
    if version_problem:
        print(f"so101 {command}: {version_problem}", file=sys.stderr)
        return None
    try:
        calibration = args.calibration and str(args.calibration.expanduser().resolve())
        node_env = {"SO101_MODE": resolved_mode, "SO101_LANG": args.lang,
                    **body_node_env(body, args.port, calibration)}
    except ValueError as error:
        print(f"so101 {command}: {error}", file=sys.stderr)
        return None
    # On a cluster this machine's daemon holds the port, and the prompt joins through it.
    port_problem = port_held_problem(TEXT[args.lang]["port_held"]) if getattr(args, "coordinator", None) is None else None
    if port_problem:
        print(f"so101 {command}: {port_problem}", file=sys.stderr)
        return None
    env = env_with_bin_first(dict(os.environ, SO101_MODE=resolved_mode, SO101_LANG=args.lang))
    return Launch(body, resolved_mode, node_env, env, args.log.expanduser().resolve())


def run_beside(launch: Launch, descriptor: dict, node_file: Path, text: dict[str, str],
               ready_marks: tuple[tuple[str, ...], ...] = (LOADED_MARKS,), also_say: str = "",
               place: ClusterPlace | None = None) -> int:
    """`dora run` of `descriptor` in the background, then `node_file` (a dynamic node) in the
    foreground once the log has one line of each of `ready_marks` (the body's, the leader's); the
    dataflow stops when that node exits; `also_say` is printed once it is ready. Returns its exit code.
    On the cluster at `place`: `dora start --attach`, every node on this machine's daemon but the policy
    (on place.policy_machine, if it names one); the dynamic node joins through this machine's daemon
    (dora's default local port, or SO101_DAEMON_PORT)."""
    with tempfile.TemporaryDirectory(prefix="so101-teleop-") as work_dir:
        dataflow: Dataflow
        if place is None:
            dataflow = Dataflow(write_dataflow(descriptor, Path(work_dir) / "dataflow.yml"), launch.log, launch.env,
                                ready_marks)
        else:
            try:
                cluster, _ = joined_cluster(place, Path(work_dir) / "cluster")
            except ClusterError as error:
                print(f"so101 teleop: {error}", file=sys.stderr, flush=True)
                return 1
            elsewhere, hints = {}, {}
            if place.policy_machine:
                elsewhere[POLICY_NODE_ID] = place.policy_machine
                policy = next(node for node in descriptor["nodes"] if node["id"] == POLICY_NODE_ID)
                hints[POLICY_NODE_ID] = f"is {policy['path']} there, and {policy['args']}?"
            copy = write_dataflow(placed(descriptor, place.here, elsewhere), Path(work_dir) / "dataflow.yml")
            dataflow = AttachedDataflow(cluster, copy, f"teleop-{os.getpid()}", launch.log, ready_marks, hints)
        ready_line = ("ready_leader" if LEADER_READY_MARKS in ready_marks else "ready" if launch.body.simulated
                      else "ready_real")
        return _run_node(dataflow, node_file, launch.env, text, launch.log, ready_line, also_say)


def task_problem(args: argparse.Namespace, body: BodyKind) -> str | None:
    """Why --task and --seed cannot be as given, in one line; None when they can (or are not given)."""
    if args.task is None:
        return "--seed goes with --task NAME" if args.seed is not None else None
    if not body.simulated:
        return (f"--task {args.task} is for a simulated body (--body pybullet or mujoco): nothing reports where a real "
                "cube is, so the real arm has no task scene and no object_state")
    return None


class _HungUp(Exception):
    """SIGHUP (the terminal closed) or SIGTERM: stop the dataflow anyway."""


def _hang_up(signum, frame):
    raise _HungUp(signum)


def _show(line: str) -> None:
    if not line:  # a text left empty on purpose (so101 replay keeps its last line last)
        return
    try:
        print(line, flush=True)
    except OSError:  # the terminal is gone: the clean-up must go on
        pass


def _run_node(dataflow: Dataflow, node_file: Path, env: dict[str, str], text: dict, log: Path, ready_line: str,
              also_say: str = "") -> int:
    # dora runs in a session of its own and gets no hang-up from the terminal: teleop must stop it.
    signal.signal(signal.SIGHUP, _hang_up)
    signal.signal(signal.SIGTERM, _hang_up)
    prompt = None
    try:
        ready = dataflow.wait_ready(START_TIMEOUT_S)
        refusal = refusal_in(log) if ready is False else None
        if refusal:  # a node said why in one line: that line, not dora's backtraces of the others
            print(f"so101 teleop: {refusal} ({log})", file=sys.stderr, flush=True)
            return 1
        # Another dataflow took dora's port between the check in `prepare` and this start.
        if ready and DAEMON_PORT_TAKEN_MARK in log.read_text(encoding="utf-8", errors="replace"):
            problem = port_held_problem(text["port_held"]) or DAEMON_PORT_TAKEN_MARK
            print(f"so101 teleop: {problem}", file=sys.stderr, flush=True)
            return 1
        failure = dataflow.failure() if isinstance(dataflow, AttachedDataflow) and not ready else None
        if failure:  # a daemon could not start a node: dora's line, not its backtrace
            print(f"so101 teleop: {failure}", file=sys.stderr, flush=True)
            return 1
        if not ready:
            message = (text["exited"].format(code=dataflow.process.returncode, log=log) if ready is False
                       else text["timeout"].format(seconds=START_TIMEOUT_S, log=log))
            print(f"so101 teleop: {message}\n{log_tail(log)}", file=sys.stderr, flush=True)
            return 1
        _show(text[ready_line])
        _show(also_say)
        prompt = subprocess.Popen([sys.executable, str(node_file)], env=env)
        # Ctrl-C at the terminal goes to the whole foreground group: the prompt quits on it,
        # teleop must outlive it to stop the dataflow.
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            prompt_code = prompt.wait()
        finally:
            signal.signal(signal.SIGINT, previous)
        return prompt_code
    except KeyboardInterrupt:
        _show(f"\n{text['interrupted']}")
        return 130
    except _HungUp as hang_up:
        return 128 + hang_up.args[0]
    finally:
        # A second Ctrl-C, or the hang-up a closing terminal sends twice (the kernel's and the shell's),
        # must not cut the clean-up short and leave dora running.
        ending = (signal.SIGINT, signal.SIGHUP, signal.SIGTERM)
        handlers = {signum: signal.signal(signum, signal.SIG_IGN) for signum in ending}
        try:
            if prompt is not None and prompt.poll() is None:
                prompt.terminate()
                prompt.wait()
            _show(text["stopping"])
            dataflow.stop()
        finally:
            for signum, handler in handlers.items():
                signal.signal(signum, handler)
        _show(text["stopped"])
