"""Running the project in tests: `so101` as a user runs it, the simulation node in-process
under MockNode, and the real dataflow.yml under `dora run` (a copy with absolute paths and
extra nodes); the course's commands typed into the prompt, and the arm checked after each.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import time
from contextlib import contextmanager
from pathlib import Path

import pyarrow as pa
import pytest

from so101.bodies.registry import BODIES
from so101.lang import LOCALE_VARS
from so101.runtime.dataflow import TICK_PERIOD_S, dataflow_copy, write_dataflow
from so101.runtime.venv import BIN as VENV_BIN, env_with_bin_first

ROOT = Path(__file__).resolve().parents[2]
RECORDER = ROOT / "tests" / "nodes" / "state_recorder.py"
SO101 = VENV_BIN / "so101"
# The keyboard prompt as a person starts it in the second terminal (it joins a running dataflow).
PROMPT_COMMAND = [str(VENV_BIN / "python"), str(ROOT / "nodes" / "keyboard_control.py")]

# The simulation node's input as dataflow.yml declares it, and one tick of that timer.
TICK_TIMER_CONFIG = {"inputs": {"tick": {"source": f"dora/timer/millis/{TICK_PERIOD_S * 1000:g}", "queue_size": 1}}}
TICK = ("tick", pa.array([], type=pa.null()))


@contextmanager
def body_environment(body: str, tmp_path: Path):
    """What a body's node needs besides its dataflow file: (environment, emulated arm or None).
    Nothing for a simulation; for the real arm, `so101 fake-arm`'s emulated bus, calibrated,
    its calibration file and a goal speed that keeps the tests' waits short; the arm's own retries."""
    from so101.bodies.registry import BODIES

    if BODIES[body].simulated:
        yield {}, None
        return
    from so101.feetech.calibration import save_calibration
    from so101.feetech.fake_arm import FakeArmProcess, calibrate_as_at_the_factory

    with FakeArmProcess() as arm:
        calibration_file = tmp_path / "so101_follower.json"
        save_calibration(calibration_file, calibrate_as_at_the_factory(arm))
        yield {"SO101_PORT": arm.port, "SO101_CALIBRATION": str(calibration_file), "SO101_MAX_SPEED_DEG_S": "180"}, arm


def run_simulation_node(monkeypatch, events, node_config=TICK_TIMER_CONFIG, body="pybullet", on_send=None, **env):
    """Run a body's node (so101.bodies.registry; nodes/simulation_node.py by default) headless over
    `events`; returns (exit code, the MockNode). The real arm's ticks come at the timer's pace,
    for its emulated servos move in wall-clock time. `on_send(output, metadata)` sees each output
    as it goes (MockNode keeps the values, not their metadata)."""
    import importlib

    from dora.testing import MockNode

    from so101.bodies.registry import BODIES
    from so101.runtime.dataflow import timer_period_s

    body_node = importlib.import_module(f"nodes.{BODIES[body].node_file.stem}")
    monkeypatch.setenv("SO101_MODE", "direct")
    monkeypatch.setenv("SO101_LANG", "en")
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    node = MockNode(events, node_config=node_config)
    if on_send is not None:
        keep = node.send_output

        def send_output(output_id, data, metadata=None):
            on_send(output_id, metadata or {})
            keep(output_id, data, metadata)

        node.send_output = send_output
    if not BODIES[body].simulated:
        node = _paced(node, timer_period_s(node_config) or TICK_PERIOD_S)
    monkeypatch.setattr(body_node, "Node", lambda: node)
    return body_node.main(), node


def _paced(node, period_s: float):
    """`node` (a MockNode) with each tick delivered no sooner than `period_s` after the last."""
    from dora.testing import MockNode

    class PacedMockNode(type(node)):
        def __next__(self):
            event = MockNode.__next__(self)
            if event.get("id") == "tick":
                now = time.monotonic()
                self.next_tick_at = max(getattr(self, "next_tick_at", now), now)
                time.sleep(self.next_tick_at - now)
                self.next_tick_at += period_s
            return event

    node.__class__ = PacedMockNode
    return node


def dora_env(**extra: str) -> dict[str, str]:
    """The environment for dora: this interpreter's bin first on PATH (dora starts nodes with that python)."""
    env = env_with_bin_first()
    env.pop("DISPLAY", None)
    env.update(extra)
    return env


def prompt_env(tmp_path: Path, **extra: str) -> dict[str, str]:
    """The prompt's environment in a test: English replies, poses, history and dora's log lines kept in tmp_path."""
    return dora_env(
        SO101_LANG="en", SO101_POSES_FILE=str(tmp_path / "poses.json"),
        SO101_HISTORY_FILE=str(tmp_path / "history"), SO101_PROMPT_LOG=str(tmp_path / "prompt.log"), **extra,
    )


def run_so101(*args: str, **env: str) -> subprocess.CompletedProcess:
    """`so101 ARGS` as a user runs it from this venv: no DISPLAY, no SO101_LANG, SO101_MODE or locale
    from the test's own shell (so the language is zh, the course's), `env` on top."""
    environ = dora_env()
    for name in ("SO101_LANG", "SO101_MODE", *LOCALE_VARS):
        environ.pop(name, None)
    environ.update(env)
    return subprocess.run([str(SO101), *args], capture_output=True, text=True, env=environ, timeout=120)


def error_lines(stderr: str) -> list[str]:
    """stderr without the build-time banner pybullet prints when it is imported."""
    return [line for line in stderr.splitlines() if not line.startswith("pybullet build time")]


# A mesh to break in tests of the model's one-line errors.
BROKEN_MESH = "assets/upper_arm_so101_v1.stl"


def copy_model(copy: Path) -> Path:
    """A copy of the verified model's files (not what is derived from them) in the folder `copy`."""
    from so101 import assets

    model = assets.urdf_path().parent
    for relpath in assets.manifest():
        (copy / relpath).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(model / relpath, copy / relpath)
    return copy


def corrupt(path: Path) -> None:
    """Flip one byte in the middle of the file."""
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))


def unused_display() -> str:
    """A `:N` display with no X server behind it (its socket absent on this machine)."""
    number = 90
    while Path(f"/tmp/.X11-unix/X{number}").exists():
        number += 1
    return f":{number}"


def write_test_dataflow(tmp_path: Path, sim_env: dict[str, str] | None = None, record_file: Path | None = None,
                        body: str = "pybullet", leader_env: dict[str, str] | None = None,
                        web_env: dict[str, str] | None = None) -> Path:
    """A body's dataflow file (dataflow.yml by default) with absolute node paths, the simulation
    forced headless, optionally the leader node driving it (`leader_env`: its settings), the web
    view (`web_env`) and a recorder node."""
    from so101.bodies.registry import BODIES
    from so101.runtime.dataflow import with_leader, with_web_view

    descriptor = dataflow_copy({"SO101_MODE": "direct", **(sim_env or {})}, BODIES[body].dataflow_file)
    if leader_env is not None:
        with_leader(descriptor, BODIES[body].node_id, leader_env)
    if web_env is not None:
        with_web_view(descriptor, BODIES[body].node_id, web_env)
    if record_file is not None:
        descriptor["nodes"].append(
            {
                "id": "recorder",
                "path": str(RECORDER),
                "inputs": {"joint_state": f"{BODIES[body].node_id}/joint_state"},
                "env": {"RECORD_FILE": str(record_file)},
            }
        )
    return write_dataflow(descriptor, tmp_path / "dataflow.yml")


class DoraRun:
    """`dora run` in the background, its log in a file; stopped with Ctrl-C (SIGINT) like a person would."""

    def __init__(self, dataflow: Path, log_path: Path, stop_after_s: float = 60, **env: str):
        self.log_path = log_path
        self._log = log_path.open("wb")
        self.process = subprocess.Popen(
            [str(VENV_BIN / "dora"), "run", str(dataflow), "--stop-after", f"{stop_after_s:g}s"],
            cwd=dataflow.parent, stdout=self._log, stderr=subprocess.STDOUT, env=dora_env(**env),
            start_new_session=True,
        )

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")

    def wait_for(self, text: str, timeout_s: float = 30) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if text in self.log():
                return
            if self.process.poll() is not None:
                raise AssertionError(f"dora run exited ({self.process.returncode}) before {text!r}:\n{self.log()[-3000:]}")
            time.sleep(0.1)
        raise AssertionError(f"{text!r} not seen in {timeout_s}s:\n{self.log()[-3000:]}")

    def stop(self, timeout_s: float = 20) -> int:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                os.killpg(self.process.pid, signal.SIGKILL)
                self.process.wait()
        self._log.close()
        return self.process.returncode


# The course's commands typed into the prompt, and the arm checked after each (test_dataflow, test_cluster).

SETTLE_S = 1.5  # 90° at the course's 3 rad/s takes 0.52 s; the rest is margin
BATCH = [-30.0, 45.0, -60.0, 30.0, 0.0]
# The commands, in order; `go a` goes to wherever `save a` found the arm.
SCRIPT = ["0 90", "batch -30 45 -60 30 0", "save a", "home", "go a"]
# MuJoCo's MJCF servos (kp 17.8 N·m/rad) give under gravity: shoulder_lift settles about
# 2.5° off the course's batch. PyBullet's course motors hold within 0.1°. The emulated servos
# (so101 fake-arm) carry no load: they reach a goal to the step (0.09°).
GRAVITY_SAG_BOUND_DEG = {"pybullet": 1.0, "mujoco": 3.0, "real": 0.2}


def settled_in_process(body: str, targets_deg: list[float]) -> list[float]:
    """Where the body itself, with no dataflow, holds the arm for these arm targets (gripper at 0)."""
    if not BODIES[body].simulated:
        return list(targets_deg)  # the emulator has no gravity: the goal itself
    with BODIES[body].body_class()(mode="direct", time_step_s=0.004, log=lambda message: None) as sim:
        sim.set_targets_deg(list(targets_deg) + [0.0])
        sim.step(round(SETTLE_S / 0.004))
        return list(sim.joint_angles_deg()[:5])


def type_the_script(tmp_path, env: dict[str, str]) -> tuple[list[float], float]:
    """SCRIPT typed into a prompt started with `env`, SETTLE_S apart; returns when each line was
    sent, and the end."""
    prompt = subprocess.Popen(
        PROMPT_COMMAND, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        env=env, cwd=tmp_path,
    )
    sent_at = []
    for command in SCRIPT:
        time.sleep(SETTLE_S if sent_at else 1.0)
        sent_at.append(time.monotonic())
        prompt.stdin.write(command + "\n")
        prompt.stdin.flush()
    time.sleep(SETTLE_S)
    end = time.monotonic()
    prompt.stdin.close()
    prompt_output = prompt.stdout.read()
    assert prompt.wait(20) == 0, prompt_output
    assert "Traceback" not in prompt_output, prompt_output
    return sent_at, end


def check_the_record(record_file, poses_file, body: str, sent_at: list[float], end: float) -> None:
    # `save a` stored the state it had reached, from joint_state.
    saved = json.loads(poses_file.read_text())
    assert list(saved) == ["a"]
    saved_deg = saved["a"]["joints_deg"]
    targets = {"0 90": [90.0, 0, 0, 0, 0], "batch -30 45 -60 30 0": BATCH, "save a": BATCH, "home": [0.0] * 5,
               "go a": saved_deg}

    samples = json.loads(record_file.read_text())["samples"]
    windows = list(zip(sent_at, sent_at[1:] + [end]))
    for command, (start, stop) in zip(SCRIPT, windows):
        in_window = [state for t, state in samples if start < t < stop]
        assert in_window, f"no joint_state between sending {command!r} and the next command"
        reached = in_window[-1]
        # The node adds nothing to the physics: the arm holds where the body holds it by itself ...
        expected = settled_in_process(body, targets[command])
        assert reached == pytest.approx(expected, abs=1.0), f"{body}, after {command!r}: {reached}, the body alone {expected}"
        # ... and that is the target, but for what gravity takes off a soft servo.
        assert reached == pytest.approx(targets[command], abs=GRAVITY_SAG_BOUND_DEG[body]), f"{body}, after {command!r}"
    assert saved_deg == pytest.approx(BATCH, abs=GRAVITY_SAG_BOUND_DEG[body])
