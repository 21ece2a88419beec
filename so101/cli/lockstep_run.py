"""What `so101 eval` and `so101 demos` share: a lockstep dataflow of a body, a driver and the episodes'
runner (nodes/episodes.py), run with `dora run` while each episode's line is shown as it ends.

The graph: the body (its node file, SO101_LOCKSTEP_FPS set) publishes each frame; the driver
(nodes/expert.py) answers it on `action`; the runner records and judges the frame and passes
the action on as the body's `joint_cmd`, or ends the episode and lays out the next. With
`--idle` there is no driver: the runner holds the arm at home.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from so101.bodies.registry import BODIES, SIMULATED_BODIES, BodyKind
from so101.cli.argtypes import add_language_option, number, whole_number
from so101.runtime.dataflow import ROOT, write_dataflow
from so101.runtime.lockstep import DEFAULT_LOCKSTEP_FPS
from so101.tasks import TASKS
from so101.tasks.episodes import Outcome, read_outcomes

EXPERT_NODE_FILE = ROOT / "nodes" / "expert.py"
EPISODES_NODE_FILE = ROOT / "nodes" / "episodes.py"
BODY_FRAME_OUTPUTS = ["joint_state", "gripper_state", "object_state", "task_status"]
DEFAULT_TIME_LIMIT_S = 30.0
# A run whose dataflow said nothing for this long (no episode ended, dora did not exit) is stuck.
STALL_S = 300.0


def add_common_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--task", choices=sorted(TASKS), required=True, help="the task (cube_to_box)")
    parser.add_argument("--episodes", type=whole_number(1, 100_000), default=10, metavar="N",
                        help="how many episodes (default 10)")
    parser.add_argument("--seed", type=whole_number(0, 2**31), default=0, metavar="S",
                        help="episode i is laid out from seed S + i (default 0)")
    parser.add_argument("--body", choices=[*SIMULATED_BODIES, "real"], default="pybullet",
                        help="the simulator (default pybullet); the real arm is refused: it has no object state")
    parser.add_argument("--time-limit", type=number(lambda value: 0 < value <= 3600, "a number of seconds above 0, at most 3600"),
                        default=DEFAULT_TIME_LIMIT_S, metavar="SECONDS",
                        help=f"simulated seconds an episode may take before it fails (default {DEFAULT_TIME_LIMIT_S:g})")
    parser.add_argument("--noise", type=number(lambda value: 0 <= value <= 10, "a scale from 0 to 10"), default=0.0,
                        metavar="SCALE", help="the expert's perturbations, as a multiple of its standard ones (default 0)")
    add_language_option(parser, "the nodes' logs")
    parser.add_argument("--log", type=Path, default=None, metavar="FILE",
                        help="dora's log (default: run.log in the run's work folder under out/)")


@dataclass(frozen=True)
class Flow:
    """One lockstep run: its body, whether an expert drives, and the runner's settings."""

    body: BodyKind
    expert: bool
    runner_env: dict[str, str]
    expert_env: dict[str, str]
    lang: str
    pictures: tuple[str, ...] = ()  # the body's picture outputs: "image", "wrist_image"
    picture_size: str = ""  # WIDTHxHEIGHT


def queued(source: str) -> dict:
    return {"source": source, "queue_size": 100, "queue_policy": "backpressure"}


def flow_for(args: argparse.Namespace, work: Path, expert: bool, pictures: tuple[str, ...],
             picture_size: tuple[int, int] | None, **runner_env: str) -> Flow:
    """The run add_common_arguments' options ask for: `pictures` (the body's picture outputs) at
    `picture_size` (None: none), the runner's results in `work`, and its own settings `runner_env`."""
    size = f"{picture_size[0]}x{picture_size[1]}" if picture_size else ""
    runner_env = {"SO101_TASK": args.task, "SO101_SEED": str(args.seed), "SO101_EPISODES": str(args.episodes),
                  "SO101_TIME_LIMIT_S": repr(args.time_limit), "SO101_EPISODES_OUT": str(work / "episodes.jsonl"),
                  "SO101_LOCKSTEP_PICTURES": size, **runner_env}
    return Flow(BODIES[args.body], expert=expert, runner_env=runner_env,
                expert_env={"SO101_TASK": args.task, "SO101_EXPERT_NOISE": repr(args.noise)}, lang=args.lang,
                pictures=pictures if size else (), picture_size=size)


def lockstep_dataflow(flow: Flow) -> dict:
    """The dataflow's descriptor: the body, the driver and the runner, every node's path absolute."""
    body_id = flow.body.node_id
    frame_outputs = [*BODY_FRAME_OUTPUTS, *flow.pictures]
    runner_inputs = {output: queued(f"{body_id}/{output}") for output in frame_outputs}
    nodes = [{
        "id": body_id, "path": str(flow.body.node_file), "restart_policy": "never",
        "inputs": {"joint_cmd": queued("episodes/joint_cmd"), "task_cmd": queued("episodes/task_cmd")},
        "outputs": frame_outputs,
        "env": {"SO101_MODE": "direct", "SO101_LANG": flow.lang, "SO101_TASK": flow.runner_env["SO101_TASK"],
                "SO101_SEED": flow.runner_env["SO101_SEED"], "SO101_LOCKSTEP_FPS": str(DEFAULT_LOCKSTEP_FPS),
                "SO101_LOCKSTEP_PICTURES": flow.picture_size},
    }]
    if flow.expert:
        runner_inputs["action"] = queued("expert/joint_cmd")
        nodes.append({
            "id": "expert", "path": str(EXPERT_NODE_FILE), "restart_policy": "never",
            "inputs": {name: queued(f"{body_id}/{name}") for name in ("joint_state", "gripper_state", "object_state")},
            "outputs": ["joint_cmd"],
            "env": {"SO101_LANG": flow.lang, "SO101_LOCKSTEP_FPS": str(DEFAULT_LOCKSTEP_FPS), **flow.expert_env},
        })
    nodes.append({
        "id": "episodes", "path": str(EPISODES_NODE_FILE), "restart_policy": "never",
        "inputs": runner_inputs, "outputs": ["joint_cmd", "task_cmd"],
        "env": {"SO101_LANG": flow.lang, "SO101_LOCKSTEP_FPS": str(DEFAULT_LOCKSTEP_FPS),
                **({} if flow.expert else {"SO101_IDLE": "1"}), **flow.runner_env},
    })
    return {"nodes": nodes}


def refuse_real(command: str, body: str) -> str | None:
    if body == "real":
        return (f"so101 {command}: the real arm has no object state (where the cube is, whether it is in the box): "
                f"{command} runs on {' or '.join(SIMULATED_BODIES)}")
    return None


def work_folder(command: str) -> Path:
    folder = ROOT / "out" / f"{command}-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}"
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def run_flow(command: str, flow: Flow, work: Path, log: Path | None, show: Callable[[Outcome], None]) -> tuple[list[Outcome], str | None]:
    """Run `flow` to its end, showing each outcome as it comes: (outcomes, None), or what went wrong in one line."""
    from so101.cli.teleop import TEXT as TELEOP_TEXT, Dataflow, _refusal, port_held_problem
    from so101.runtime.venv import dora_executable, env_with_bin_first
    from so101.runtime.versions import dora_version_problem

    version_problem = dora_version_problem(dora_executable())
    if version_problem:
        return [], version_problem
    port_problem = port_held_problem(TELEOP_TEXT[flow.lang]["port_held"])
    if port_problem:
        return [], port_problem
    results = Path(flow.runner_env["SO101_EPISODES_OUT"])
    results.unlink(missing_ok=True)
    dataflow_file = write_dataflow(lockstep_dataflow(flow), work / "dataflow.yml")
    log_file = (log or work / "run.log").expanduser().resolve()
    env = env_with_bin_first(dict(os.environ, SO101_LANG=flow.lang))
    dataflow = Dataflow(dataflow_file, log_file, env, ())
    shown = 0
    outcomes: list[Outcome] = []
    done = False
    last_news = time.monotonic()
    try:
        while True:
            exited = dataflow.process.poll() is not None
            try:
                outcomes, done = read_outcomes(results.read_text(encoding="utf-8").splitlines())
            except (OSError, ValueError, TypeError):
                outcomes, done = outcomes, False
            for outcome in outcomes[shown:]:
                show(outcome)
                last_news = time.monotonic()
            shown = len(outcomes)
            if exited or done:
                break
            if time.monotonic() - last_news > STALL_S:
                return outcomes, f"no episode ended for {STALL_S:g} s: see {log_file}"
            time.sleep(0.1)
        if done:
            deadline = time.monotonic() + 20
            while dataflow.process.poll() is None and time.monotonic() < deadline:
                time.sleep(0.1)
    finally:
        code = dataflow.process.poll()
        dataflow.stop()
    if not done:
        refusal = _refusal(log_file)
        return outcomes, refusal or f"the dataflow ended (exit code {code}) before its episodes did: see {log_file}"
    return outcomes, None


def fail(line: str) -> int:
    print(line, file=sys.stderr)
    return 1
