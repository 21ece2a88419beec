"""Course steps A and B as commands: `so101 inspect` and `so101 joints`.

The course runs these as `test_so101.py` and `test_so101_joints.py`; the same
scripts, readable, are in examples/, and share the set-up and stepping at the
end of this file.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

from so101.assets import ModelFilesError, urdf_path
from so101.runtime.argtypes import add_language_option
from so101.robot import ACTUATED_JOINTS, NUM_ARM_JOINTS
from so101.runtime.display import MODE_ENV_VAR, MODES, DisplayError, resolve_mode

COURSE_STEP_B_TARGETS_RAD = (0.5, -0.5, 0.5, -0.5, 0.5)
COURSE_STEP_B_STEPS = 500
COURSE_TIME_STEP_S = 1.0 / 240.0

TYPE_LABELS = {
    "zh": {"revolute": "旋转关节 (Revolute)", "prismatic": "棱柱关节 (Prismatic)", "fixed": "固定关节 (Fixed)"},
    "en": {"revolute": "revolute", "prismatic": "prismatic", "fixed": "fixed"},
}


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    parser.add_argument(
        "--mode", choices=MODES, default="auto",
        help="gui opens a window; direct is headless; auto (default) picks gui where a display is available",
    )
    add_language_option(parser, "the printed text")
    parser.add_argument(
        "--steps", type=int, default=None,
        help="simulate this many steps after printing, then exit (default: until Ctrl-C with a window, "
        "240 = 1 s headless)",
    )
    if name == "joints":
        parser.add_argument(
            "--targets", type=float, nargs=NUM_ARM_JOINTS, metavar="RAD", default=COURSE_STEP_B_TARGETS_RAD,
            help="target angles of joints 0-4 in radians (default: the course's 0.5 -0.5 0.5 -0.5 0.5)",
        )
        parser.add_argument(
            "--drive-steps", type=int, default=COURSE_STEP_B_STEPS,
            help=f"steps to drive before reading the angles (default {COURSE_STEP_B_STEPS}, as in the course)",
        )
    parser.set_defaults(step=name)


def print_joint_table(sim, lang: str) -> None:
    labels = TYPE_LABELS[lang]
    if lang == "zh":
        print(f"SO-101 已加载,robot_id = {sim.robot_id}")
        print(f"关节数量: {len(sim.joints)}\n")
    else:
        print(f"SO-101 loaded, robot_id = {sim.robot_id}")
        print(f"joints: {len(sim.joints)}\n")
    for joint in sim.joints:
        kind = labels.get(joint.type, joint.type)
        limits = ""
        if joint.type == "revolute":
            limits = f"  [{math.degrees(joint.lower_rad):7.1f}°, {math.degrees(joint.upper_rad):6.1f}°]"
        word, type_word = ("关节", "类型") if lang == "zh" else ("joint", "type")
        print(f"  {word} {joint.index}: {joint.name:22s} {type_word}: {kind}{limits}")


def print_angles(sim, lang: str) -> None:
    print("\n当前关节角度:" if lang == "zh" else "\njoint angles now:")
    word = "关节" if lang == "zh" else "joint"
    for joint, angle in zip(ACTUATED_JOINTS[:NUM_ARM_JOINTS], sim.joint_angles_deg()):
        print(f"  {word} {joint.index}: {angle:.1f}°")


def keep_running(sim, steps: int | None, lang: str) -> None:
    """Step in real time: forever (until Ctrl-C) with a window, else `steps` (240 headless by default)."""
    if steps is None:
        steps = None if sim.display_mode == "gui" else 240
    if steps is None:
        print("\n运行中... 按 Ctrl+C 退出" if lang == "zh" else "\nrunning... press Ctrl+C to quit", flush=True)
    count = 0
    try:
        while steps is None or count < steps:
            sim.step()
            count += 1
            if sim.display_mode == "gui":
                time.sleep(sim.time_step_s)
    except KeyboardInterrupt:
        print("\n停止仿真" if lang == "zh" else "\nsimulation stopped")


def run(args: argparse.Namespace) -> int:
    from so101.bodies.pybullet_sim import SO101Sim  # imported here: pybullet prints a banner on import

    with SO101Sim(mode=args.mode, time_step_s=COURSE_TIME_STEP_S) as sim:
        if args.step == "inspect":
            print_joint_table(sim, args.lang)
        else:
            sim.set_targets_deg([math.degrees(angle) for angle in args.targets] + [0.0])
            sim.step(args.drive_steps)
            print_angles(sim, args.lang)
        keep_running(sim, args.steps, args.lang)
    return 0


# -- for the course scripts in examples/, which use PyBullet's default client directly ------------


def open_course_world(script: str) -> tuple[str, Path]:
    """Check the model and the display, then connect and lay the course's ground: (mode, URDF path).

    The PyBullet calls are the course's: connect, setAdditionalSearchPath, setGravity
    and loadURDF("plane.urdf"). A missing model or display is one line on stderr,
    naming `script`, and exit status 2.
    """
    import pybullet as p  # here, as in run(): pybullet prints a banner on import
    import pybullet_data

    try:
        urdf = urdf_path()
        mode, notice = resolve_mode(os.environ.get(MODE_ENV_VAR, "auto"))
    except (ModelFilesError, DisplayError, ValueError) as error:
        print(f"{script}: {error}", file=sys.stderr)
        raise SystemExit(2) from None
    if notice:
        print(notice)
    p.connect(p.GUI if mode == "gui" else p.DIRECT)
    p.setAdditionalSearchPath(pybullet_data.getDataPath())  # where plane.urdf lives
    p.setGravity(0, 0, -9.81)
    p.loadURDF("plane.urdf")
    return mode, urdf


def step_course_world(mode: str, steps: int | None, waiting: str) -> bool:
    """Step `steps` times, or with None until Ctrl-C after printing `waiting`; True if Ctrl-C stopped it.

    Real time (1/240 s a step) only with a window: headless runs flat out.
    """
    import pybullet as p

    if steps is None:
        print(waiting, flush=True)
    count = 0
    try:
        while steps is None or count < steps:
            p.stepSimulation()
            count += 1
            if mode == "gui":
                time.sleep(COURSE_TIME_STEP_S)
    except KeyboardInterrupt:
        return True
    return False
