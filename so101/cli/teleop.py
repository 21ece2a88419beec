"""`so101 teleop`: the dataflow and the keyboard prompt in one terminal.

Starts `dora run` in the background with its log in a file, waits until the
simulation has loaded the arm, runs the prompt (`nodes/keyboard_control.py`) in
the foreground, and stops the dataflow when the prompt exits (quit, Ctrl-D,
Ctrl-C), leaving no process behind.

dora gives a node the `env:` of dataflow.yml over the environment it was started
with, so `--mode` and `--lang` cannot reach the simulation as inherited variables:
teleop runs a copy of dataflow.yml (in a temporary folder, removed at exit) with
those two values set and the node paths made absolute. The file itself stays as the course has it.

`--leader PORT --leader-calibration FILE` puts the leader node between the prompt and the body
(dataflow_leader.yml's graph, on whichever body `--body` chose): the leader arm drives, and typed
motion commands take over until the leader moves again.

`--task NAME [--seed N]` puts a task's scene (so101.tasks) on a simulated body's floor: the body
publishes `object_state` and `task_status`, and the prompt's `reset [SEED]` and `task` talk to it.

`--record DIR` adds the recorder node (and, for a simulation, the camera node that draws its
pictures) to that copy: the prompt's `record`, `stop`, `discard` and `episodes` then keep
episodes in DIR as a LeRobot dataset.
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from so101.bodies.registry import BODIES, DEFAULT_BODY, BodyKind, body_node_env
from so101.dataset.features import DEFAULT_FPS, video_keys_and_sizes
from so101.dataset.settings import DEFAULT_IMAGE_SIZE
from so101.runtime.dataflow import (
    LEADER_READY_MARKS, LOADED_MARKS, POLICY_READY_MARKS, PROMPT_NODE_FILE, ROOT, WEB_VIEW_MARKS, dataflow_copy,
    with_expert, with_leader, with_policy, with_recorder, with_task, with_web_view, write_dataflow,
)
from so101.runtime.display import MODES, resolve_mode
from so101.web.settings import (
    DEFAULT_HOST as DEFAULT_WEB_HOST, DEFAULT_PORT as DEFAULT_WEB_PORT, EVERY_ADDRESS, LOCAL_HOSTS, page_address,
)
from so101.prompt.join import port_holder
from so101.runtime.processes import DAEMON_PORT_TAKEN_MARK, alive, descendants, kill_until_gone, stop_process, who_runs
from so101.cli.argtypes import add_language_option, image_size, torch_device, whole_number
from so101.tasks import TASKS, parse_seed, task_named
from so101.runtime.venv import dora_executable, env_with_bin_first
from so101.runtime.versions import DAEMON_DEFAULT_LOCAL_PORT, dora_version_problem

DEFAULT_LOG = ROOT / "out" / "teleop-dora.log"
START_TIMEOUT_S = 90.0
STOP_TIMEOUT_S = 20.0
# How long a node may take to end after dora stopped, before it is killed (the real arm switches torque off).
NODE_GRACE_S = 5.0
LOG_TAIL_LINES = 15

TEXT = {
    "zh": {
        "starting": "启动数据流(dora run,{mode} 模式),日志写入 {log}",
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


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    add_body_arguments(parser)
    add_task_arguments(parser)
    add_language_option(parser, "the prompt and the logs")
    parser.add_argument(
        "--record", type=Path, metavar="DIR", default=None,
        help="keep episodes in DIR as a LeRobot dataset (v3.0): made if missing, appended to if it is one; "
        "at the prompt: record TASK TEXT, stop, discard, episodes (jog: E)",
    )
    parser.add_argument(
        "--fps", type=whole_number(1, 1000), default=DEFAULT_FPS, metavar="N",
        help=f"--record: frames per second (default {DEFAULT_FPS}, LeRobot's)",
    )
    parser.add_argument(
        "--image-size", type=image_size, default=DEFAULT_IMAGE_SIZE, metavar="WxH",
        help=f"--record on a simulation: each camera's pictures, stored as video (default {DEFAULT_IMAGE_SIZE}; "
        "640x480 draws each picture about twice as long: `so101 bench --cameras --image-size 640x480`)",
    )
    parser.add_argument(
        "--leader", metavar="PORT", default=None,
        help="an SO-101 leader arm on PORT drives the body (with --leader-calibration; `so101 fake-arm` emulates one); "
        "typed motion commands take over until the leader moves again",
    )
    parser.add_argument(
        "--leader-calibration", type=Path, metavar="FILE", default=None,
        help="--leader: the leader's calibration JSON (from `so101 calibrate --leader`, or LeRobot's so101_leader one)",
    )
    parser.add_argument(
        "--policy", type=Path, metavar="DIR", default=None,
        help="a trained LeRobot policy (lerobot-train's .../checkpoints/last/pretrained_model) between the prompt "
        "and the body: at the prompt, policy on / policy off; a typed move takes over",
    )
    parser.add_argument("--policy-python", type=Path, metavar="PY", default=None,
                        help="--policy: the Python that runs it, with LeRobot (default: so101 policy-env's)")
    parser.add_argument("--policy-device", type=torch_device, metavar="DEVICE", default="cpu",
                        help="--policy: the torch device it runs on: cpu (default), cuda or mps")
    add_web_arguments(parser)
    add_log_option(parser)


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


def _log_tail(log: Path) -> str:
    try:
        lines = log.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return ""
    return "\n".join("  " + line for line in lines[-LOG_TAIL_LINES:])


# A node's one line when it refuses to start (so101.runtime.node_events.cannot_start), or (the episodes'
# runner, the policy) to go on, as dora's log carries it.
_REFUSAL = re.compile(r"(\[\w+\] cannot (?:start|go on): .*?)\s*$", re.MULTILINE)


def _refusal(log: Path) -> str | None:
    """The first node's refusal to start in the dataflow's log, if one refused."""
    try:
        match = _REFUSAL.search(log.read_text(encoding="utf-8", errors="replace"))
    except OSError:
        return None
    return match.group(1) if match else None


class Dataflow:
    """`dora run` in its own session (so the terminal's Ctrl-C reaches only the prompt), log to a file."""

    def __init__(self, dataflow: Path, log: Path, env: dict[str, str], ready_marks: tuple[tuple[str, ...], ...]):
        log.parent.mkdir(parents=True, exist_ok=True)
        self.log = log
        self.ready_marks = ready_marks
        self._log_stream = log.open("wb")
        self.process = subprocess.Popen(
            [dora_executable() or "dora", "run", str(dataflow)], cwd=dataflow.parent,
            stdin=subprocess.DEVNULL, stdout=self._log_stream, stderr=subprocess.STDOUT,
            env=env, start_new_session=True,
        )

    def wait_ready(self, timeout_s: float) -> bool | None:
        """True once the simulation is up; False if dora exited first; None on timeout."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            log_text = self.log.read_text(encoding="utf-8", errors="replace")
            if all(any(mark in log_text for mark in marks) for marks in self.ready_marks):
                return True
            if self.process.poll() is not None:
                return False
            time.sleep(0.2)
        return None

    def stop(self) -> None:
        """Ctrl-C for dora (it stops every node), then SIGKILL for anything still alive."""
        nodes = descendants(self.process.pid)
        stop_process(self.process, STOP_TIMEOUT_S)
        kill_until_gone(lambda: [pid for pid in nodes if alive(pid)], timeout_s=5, grace_s=NODE_GRACE_S)
        self._log_stream.close()


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
    port_problem = port_held_problem(TEXT[args.lang]["port_held"])
    if port_problem:
        print(f"so101 {command}: {port_problem}", file=sys.stderr)
        return None
    env = env_with_bin_first(dict(os.environ, SO101_MODE=resolved_mode, SO101_LANG=args.lang))
    return Launch(body, resolved_mode, node_env, env, args.log.expanduser().resolve())


def port_held_problem(template: str) -> str | None:
    """Why a dataflow started now would have its prompt join another one (`template`: TEXT's "port_held"),
    in one line; None if no dataflow holds dora's port."""
    holder = port_holder()
    return template.format(port=DAEMON_DEFAULT_LOCAL_PORT, holder=who_runs(holder)) if holder else None


def run(args: argparse.Namespace) -> int:
    text = TEXT[args.lang]
    problem = task_problem(args, BODIES[args.body])
    if problem:
        print(f"so101 teleop: {problem}", file=sys.stderr)
        return 2
    launch = prepare(args, "teleop")
    if launch is None:
        return 2
    descriptor = dataflow_copy(launch.node_env, launch.body.dataflow_file)
    ready_marks: tuple[tuple[str, ...], ...] = (LOADED_MARKS,)
    if args.task is not None:
        with_task(descriptor, launch.body.node_id, args.task, args.seed or 0)
    if args.leader is not None or args.leader_calibration is not None:
        problem = add_leader(descriptor, launch.body, args.leader, args.leader_calibration, args.port, args.lang)
        if problem:
            print(f"so101 teleop: {problem}", file=sys.stderr)
            return 2
        ready_marks += (LEADER_READY_MARKS,)
    if args.task is not None:  # after the leader: a leader's move takes over from the expert, as a typed one does
        with_expert(descriptor, launch.body.node_id, {"SO101_TASK": args.task, "SO101_LANG": args.lang})
    if args.policy is not None:  # last before the body: any move before it takes over, the expert's too
        problem = add_policy(descriptor, launch.body, args)
        if problem:
            print(f"so101 teleop: {problem}", file=sys.stderr)
            return 2
        ready_marks += (POLICY_READY_MARKS,)
    elif args.policy_python is not None:
        print("so101 teleop: --policy-python goes with --policy DIR", file=sys.stderr)
        return 2
    if args.record is not None:
        problem = add_recorder(descriptor, launch.body, args.record.expanduser().resolve(), args.fps, args.lang,
                               args.task, args.image_size)
        if problem:
            print(f"so101 teleop: {problem}", file=sys.stderr)
            return 2
    web_line = add_web_view(args, descriptor, launch.body, "teleop")
    if web_line:
        ready_marks += (WEB_VIEW_MARKS,)
    print(text["starting"].format(mode=launch.mode, log=launch.log), flush=True)
    return run_beside(launch, descriptor, PROMPT_NODE_FILE, text, ready_marks, web_line)


def run_beside(launch: Launch, descriptor: dict, node_file: Path, text: dict[str, str],
               ready_marks: tuple[tuple[str, ...], ...] = (LOADED_MARKS,), also_say: str = "") -> int:
    """`dora run` of `descriptor` in the background, then `node_file` (a dynamic node) in the
    foreground once the log has one line of each of `ready_marks` (the body's, the leader's); the
    dataflow stops when that node exits; `also_say` is printed once it is ready. Returns its exit code."""
    with tempfile.TemporaryDirectory(prefix="so101-teleop-") as work_dir:
        copy = write_dataflow(descriptor, Path(work_dir) / "dataflow.yml")
        dataflow = Dataflow(copy, launch.log, launch.env, ready_marks)
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


def add_policy(descriptor: dict, body: BodyKind, args: argparse.Namespace) -> str | None:
    """The policy node added to `descriptor`, before `body`; or, in one line, why it cannot be (a folder that
    is not a policy's, features this dataflow cannot give, no Python to run it)."""
    from so101.policy.choice import choose_policy
    from so101.tasks import task_named

    names = task_named(args.task).object_state_names if args.task else ()
    try:
        chosen = choose_policy(args.policy, args.policy_python, args.task, names)
    except ValueError as error:
        return str(error)
    if chosen.picture_size is not None:
        return ("the policy sees the cameras, and at the prompt the body draws no wrist picture: score it with "
                "so101 eval --policy, where the body draws both for each frame")
    for line in chosen.notes():
        print(f"so101 teleop: {line}", flush=True)
    env = {**chosen.env(args.task or "", args.policy_device), "SO101_LANG": args.lang}
    if not args.task:
        del env["SO101_TASK"]
    with_policy(descriptor, body.node_id, chosen.inputs, env, str(chosen.python))
    return None


def add_leader(descriptor: dict, body: BodyKind, port: str | None, calibration_file: Path | None,
               follower_port: str | None, lang: str) -> str | None:
    """The leader node added to `descriptor`, driving `body`; or, in one line, why it cannot be
    (a missing option, the follower's own port, a calibration file that cannot be a leader's)."""
    from so101.feetech.calibration import CalibrationError, load_calibration

    if not port or calibration_file is None:
        return ("--leader PORT and --leader-calibration FILE go together (no leader? `so101 fake-arm` emulates one; "
                "`so101 calibrate --leader` makes the file)")
    if follower_port and os.path.realpath(port) == os.path.realpath(follower_port):
        return f"--leader {port} is the follower's --port too: the two arms are on two serial ports"
    calibration_path = calibration_file.expanduser().resolve()
    try:  # checked now, with the file's one-line error; the node checks it against the servos
        load_calibration(calibration_path, role="leader")
    except CalibrationError as error:
        return str(error)
    with_leader(descriptor, body.node_id, {"SO101_LEADER_PORT": port,
                                           "SO101_LEADER_CALIBRATION": str(calibration_path), "SO101_LANG": lang})
    return None


def add_recorder(descriptor: dict, body: BodyKind, dataset_dir: Path, fps: int, lang: str,
                 task: str | None, image_size: tuple[int, int]) -> str | None:
    """The recorder (and a simulation's camera) added to `descriptor`; or why DIR cannot take
    these episodes, in one line, before anything starts."""
    from so101.dataset.layout import DatasetError
    from so101.dataset.writer import DatasetWriter

    pictures = image_size if body.simulated else None  # the real arm has no camera of its own
    try:  # checked now, and let go: the recorder node opens it again
        DatasetWriter.open(dataset_dir, fps, video_keys_and_sizes(pictures, task is not None),
                           environment_names=task_named(task).object_state_names if task else ()).close()
    except DatasetError as error:
        return str(error)
    size_text = f"{pictures[0]}x{pictures[1]}" if pictures else ""
    recorder_env = {"SO101_RECORD_DIR": str(dataset_dir), "SO101_RECORD_FPS": str(fps),
                    "SO101_RECORD_IMAGE_SIZE": size_text, "SO101_LANG": lang}
    camera_env = {"SO101_CAMERA_BODY": body.name, "SO101_RECORD_IMAGE_SIZE": size_text} if pictures else None
    with_recorder(descriptor, body.node_id, recorder_env, camera_env, picture_hz=fps)
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
        refusal = _refusal(log) if ready is False else None
        if refusal:  # a node said why in one line: that line, not dora's backtraces of the others
            print(f"so101 teleop: {refusal} ({log})", file=sys.stderr, flush=True)
            return 1
        # Another dataflow took dora's port between the check in `prepare` and this start.
        if ready and DAEMON_PORT_TAKEN_MARK in log.read_text(encoding="utf-8", errors="replace"):
            problem = port_held_problem(text["port_held"]) or DAEMON_PORT_TAKEN_MARK
            print(f"so101 teleop: {problem}", file=sys.stderr, flush=True)
            return 1
        if not ready:
            message = (text["exited"].format(code=dataflow.process.returncode, log=log) if ready is False
                       else text["timeout"].format(seconds=START_TIMEOUT_S, log=log))
            print(f"so101 teleop: {message}\n{_log_tail(log)}", file=sys.stderr, flush=True)
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
