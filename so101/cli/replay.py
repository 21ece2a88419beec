"""`so101 replay DIR --episode N`: an episode of a LeRobot dataset played onto any body.

Runs the body's dataflow (as `so101 teleop` does, with the same --body, --port, --calibration and
--mode) with the replay node (nodes/replay.py) in the prompt's place, in the foreground: it moves
the arm slowly to the episode's first frame, plays every frame at the dataset's rate, and ends
with the tracking error and how the body followed the recording's own states. The dataset, its
episode and its joints' units (so101.dataset.units: `--units`, `--calibration`) are checked before
anything starts.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, replace
from pathlib import Path

from so101.bodies.physics import centred, physics_mode, physics_ranges
from so101.bodies.registry import BODIES
from so101.bodies.scenario import Scenario
from so101.dataset.units import UNITS, UNITS_HELP
from so101.runtime.argtypes import add_language_option, parsed_by, whole_number
from so101.launch.beside_prompt import (
    TEXT as TELEOP_TEXT, add_body_arguments, add_log_option, add_web_arguments, add_web_view, prepare, run_beside,
)
from so101.runtime.dataflow import LOADED_MARKS, REPLAY_NODE_FILE, WEB_VIEW_MARKS, dataflow_copy, tell_nodes, with_replay

TEXT = {
    lang: {**lines, "ready": "", "ready_real": "", "stopping": "", "stopped": "",
           "starting": "回放:启动数据流(dora run,{mode} 模式),日志写入 {log}" if lang == "zh"
           else "replay: starting the dataflow (dora run, {mode} mode), log in {log}"}
    for lang, lines in TELEOP_TEXT.items()
}


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    parser.add_argument("dataset", type=Path, metavar="DIR", help="the dataset's folder (LeRobotDataset v3.0)")
    parser.add_argument("--episode", type=whole_number(0, 10**9), default=0, metavar="N",
                        help="the episode to play (default 0; `so101 dataset DIR` lists them)")
    add_body_arguments(parser)
    parser.add_argument("--units", choices=UNITS, default=None, help=UNITS_HELP + "; normalized ones are made degrees "
                        "with --calibration's ranges (for a simulated body, --calibration is the recording follower's)")
    parser.add_argument("--physics", type=parsed_by(physics_mode), default=None, metavar="FILE.json|varied",
                        help="a simulated body: replay under these physics ranges' centre (the servos' delay, speed "
                             "limit, gains and the gripper's force; the calibration exact), such as a file `so101 "
                             "physics --fit` wrote, to set its `versus the recording` against the default's")
    add_language_option(parser, "the messages")
    add_web_arguments(parser)
    add_log_option(parser)


def run(args: argparse.Namespace) -> int:
    from so101.dataset.layout import DatasetError
    from so101.dataset.reader import Dataset

    dataset_dir = args.dataset.expanduser().resolve()
    calibration = args.calibration and args.calibration.expanduser().resolve()
    try:  # a wrong folder, episode or units are said here, before a dataflow starts
        dataset = Dataset.open(dataset_dir)
        dataset.episode_frames(args.episode)
        units = dataset.joint_units(args.units, calibration, args.episode)
    except DatasetError as error:
        print(f"so101 replay: {error}", file=sys.stderr)
        return 2
    print(units.how, flush=True)
    physics = replay_physics(args.physics, args.body)
    if physics is None:
        return 2
    if BODIES[args.body].simulated:  # a simulated body has no calibration of its own: it was the recording's
        args = argparse.Namespace(**{**vars(args), "calibration": None})
    launch = prepare(args, "replay", REPLAY_NODE_FILE)
    if launch is None:
        return 2
    text = TEXT[args.lang]
    descriptor = with_replay(dataflow_copy(launch.node_env, launch.body.dataflow_file), launch.body.node_id)
    if physics != "fixed":
        tell_nodes(descriptor, (launch.body.node_id,), Scenario(physics=physics).env())
    web_line = add_web_view(args, descriptor, launch.body, "replay")
    ready_marks = (LOADED_MARKS, WEB_VIEW_MARKS) if web_line else (LOADED_MARKS,)
    env = dict(launch.env, SO101_REPLAY_DIR=str(dataset_dir), SO101_REPLAY_EPISODE=str(args.episode),
               SO101_REPLAY_UNITS=args.units or "", SO101_REPLAY_CALIBRATION=str(calibration or ""))
    print(text["starting"].format(mode=launch.mode, log=launch.log), flush=True)
    return run_beside(replace(launch, env=env), descriptor, REPLAY_NODE_FILE, text, ready_marks, web_line)


def replay_physics(mode: str | None, body: str) -> str | None:
    """The body's physics as its node is told it: "fixed" without --physics, else the ranges' centre as JSON
    text, said in one line; None (after one line on stderr) where the body cannot take it."""
    if mode is None or mode == "fixed":
        return "fixed"
    if not BODIES[body].simulated:
        print("so101 replay: --physics sets a simulated body's servos: the real arm has its own", file=sys.stderr)
        return None
    ranges = physics_ranges(mode)
    if ranges is None:
        return "fixed"
    centre = centred(ranges)
    print(f"replay: physics at the ranges' centre: command delay {centre.command_delay_s[0] * 1000:.0f} ms, speed limit "
          f"{centre.speed_limit_deg_s[0]:g} deg/s, "
          + (f"servo stiffness x{centre.servo_stiffness[0]:g}" if centre.servo_time_constant_s is None else
             f"servo time constant {centre.servo_time_constant_s[0] * 1000:.0f} ms")
          + f", damping x{centre.servo_damping[0]:g}, calibration exact", flush=True)
    return json.dumps(asdict(centre), sort_keys=True)
