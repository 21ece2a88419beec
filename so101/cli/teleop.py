"""`so101 teleop`: the dataflow and the keyboard prompt in one terminal.

Starts `dora run` in the background with its log in a file, waits until the
simulation has loaded the arm, runs the prompt (`nodes/keyboard_control.py`) in
the foreground, and stops the dataflow when the prompt exits (quit, Ctrl-D,
Ctrl-C), leaving no process behind.

dora gives a node the `env:` of dataflow.yml over the environment it was started
with, so `--mode` and `--lang` cannot reach the simulation as inherited variables:
teleop runs a copy of dataflow.yml (in a temporary folder, removed at exit) with
those two values set and the node paths made absolute. The file itself stays as the course has it.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from so101.bodies.registry import BODIES, DEFAULT_BODY, body_node_env
from so101.runtime.dataflow import LOADED_MARKS, PROMPT_NODE_FILE, ROOT, dataflow_copy, write_dataflow
from so101.gui.display import MODES, resolve_mode
from so101.runtime.processes import alive, descendants, kill_until_gone, stop_process
from so101.cli.argtypes import add_language_option
from so101.runtime.venv import dora_executable, env_with_bin_first
from so101.runtime.versions import dora_version_problem

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
        "stopping": "停止数据流...",
        "stopped": "数据流已停止",
        "exited": "dora run 提前退出(退出码 {code}),日志 {log} 最后几行:",
        "timeout": "{seconds:g} 秒内仿真未就绪,日志 {log} 最后几行:",
        "interrupted": "已中断",
    },
    "en": {
        "starting": "starting the dataflow (dora run, {mode} mode), log in {log}",
        "ready": "simulation ready, starting the keyboard prompt",
        "ready_real": "the arm is ready (torque on), starting the keyboard prompt",
        "stopping": "stopping the dataflow...",
        "stopped": "dataflow stopped",
        "exited": "dora run exited early (exit code {code}); last lines of {log}:",
        "timeout": "the simulation was not ready within {seconds:g} s; last lines of {log}:",
        "interrupted": "interrupted",
    },
}


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
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
    add_language_option(parser, "the prompt and the logs")
    parser.add_argument(
        "--log", type=Path, default=DEFAULT_LOG, metavar="FILE",
        help=f"where the dataflow's log goes (default: {DEFAULT_LOG})",
    )


def _log_tail(log: Path) -> str:
    try:
        lines = log.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return ""
    return "\n".join("  " + line for line in lines[-LOG_TAIL_LINES:])


class Dataflow:
    """`dora run` in its own session (so the terminal's Ctrl-C reaches only the prompt), log to a file."""

    def __init__(self, dataflow: Path, log: Path, env: dict[str, str]):
        log.parent.mkdir(parents=True, exist_ok=True)
        self.log = log
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
            if any(mark in log_text for mark in LOADED_MARKS):
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


def run(args: argparse.Namespace) -> int:
    text = TEXT[args.lang]
    body = BODIES[args.body]
    try:
        # A GUI without a display fails here, in one line. The real arm has no window to choose.
        resolved_mode, notice = resolve_mode(args.mode) if body.simulated else ("real", None)
    except ValueError as error:  # a bad $SO101_MODE: argparse does not check defaults against choices
        print(f"so101 teleop: {error} (from --mode or $SO101_MODE)", file=sys.stderr)
        return 2
    if notice:
        print(notice, flush=True)
    dataflow_file = body.dataflow_file
    if not dataflow_file.exists() or not PROMPT_NODE_FILE.exists():
        print(f"so101 teleop: {dataflow_file} or {PROMPT_NODE_FILE} is missing: run it from a checkout of the project", file=sys.stderr)
        return 2
    # A CLI and library of different versions fail deep in the daemon; say it here, in one line.
    version_problem = dora_version_problem(dora_executable())
    if version_problem:
        print(f"so101 teleop: {version_problem}", file=sys.stderr)
        return 2
    try:
        calibration = args.calibration and str(args.calibration.expanduser().resolve())
        node_env = {"SO101_MODE": resolved_mode, "SO101_LANG": args.lang,
                    **body_node_env(body, args.port, calibration)}
    except ValueError as error:
        print(f"so101 teleop: {error}", file=sys.stderr)
        return 2
    log = args.log.expanduser().resolve()
    env = env_with_bin_first(dict(os.environ, SO101_MODE=resolved_mode, SO101_LANG=args.lang))

    print(text["starting"].format(mode=resolved_mode, log=log), flush=True)
    with tempfile.TemporaryDirectory(prefix="so101-teleop-") as work_dir:
        copy = write_dataflow(
            dataflow_copy(node_env, dataflow_file), Path(work_dir) / "dataflow.yml",
        )
        dataflow = Dataflow(copy, log, env)
        return _run_prompt(dataflow, env, text, log, body.simulated)


class _HungUp(Exception):
    """SIGHUP (the terminal closed) or SIGTERM: stop the dataflow anyway."""


def _hang_up(signum, frame):
    raise _HungUp(signum)


def _show(line: str) -> None:
    try:
        print(line, flush=True)
    except OSError:  # the terminal is gone: the clean-up must go on
        pass


def _run_prompt(dataflow: Dataflow, env: dict[str, str], text: dict, log: Path, simulated: bool) -> int:
    # dora runs in a session of its own and gets no hang-up from the terminal: teleop must stop it.
    signal.signal(signal.SIGHUP, _hang_up)
    signal.signal(signal.SIGTERM, _hang_up)
    prompt = None
    try:
        ready = dataflow.wait_ready(START_TIMEOUT_S)
        if not ready:
            message = (text["exited"].format(code=dataflow.process.returncode, log=log) if ready is False
                       else text["timeout"].format(seconds=START_TIMEOUT_S, log=log))
            print(f"so101 teleop: {message}\n{_log_tail(log)}", file=sys.stderr, flush=True)
            return 1
        _show(text["ready" if simulated else "ready_real"])
        prompt = subprocess.Popen([sys.executable, str(PROMPT_NODE_FILE)], env=env)
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
        if prompt is not None and prompt.poll() is None:
            prompt.terminate()
            prompt.wait()
        _show(text["stopping"])
        # A second Ctrl-C must not cut the clean-up short and leave dora running.
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            dataflow.stop()
        finally:
            signal.signal(signal.SIGINT, previous)
        _show(text["stopped"])
