"""simulation: the SO-101 in PyBullet as a dora node (course step C).

Each `tick` advances the physics by one step of the tick's own period (with the
course's motor calls for a new goal first) and publishes `joint_state`. A `joint_cmd` only
updates the targets; the next tick applies them. When dora had to drop ticks
because the node was late (a busy machine), the next tick takes the steps of the
dropped ones too, so simulated time keeps pace with the wall clock.

Environment (declared in dataflow.yml):
  SO101_MODE        auto | gui | direct   (auto: a window where a display exists)
  SO101_CONTROL     position | servo      (position is the course's POSITION_CONTROL)
  SO101_SERVO_ZETA  damping ratio of the servo model (servo mode only)
  SO101_IMAGE_HZ    rate of the optional `image` output, 0 = off
  SO101_FAST_STEPS  0 = paced by the tick (default); N > 0 = fast mode for batch use:
                    no wall-clock pacing, N physics steps per published state
  SO101_TICK_LOG    file to write per-tick timings and step counts to at exit, for `so101 bench`; empty = off
  SO101_LANG        zh | en               (log language)
"""

from __future__ import annotations

import os
import sys
import time
from array import array

import pyarrow as pa
from dora import Node

from so101.assets import ModelFilesError
from so101.dataflow import TICK_PERIOD_S, TickClock, timer_period_s
from so101.display import DisplayError
from so101.joint_cmd import decode_joint_cmd
from so101.robot import GRIPPER_COMMAND_INDEX, HOME_POSE_DEG, NUM_ARM_JOINTS
from so101.simulator import SO101Sim, release_freed_memory
from so101.viewer import WindowClosed

IMAGE_SIZE = (320, 240)

TEXT = {
    "zh": {
        "loaded": "[仿真节点] SO-101 加载完成,robot_id = {robot_id}({mode} 模式,步长 {step_ms:g} ms,{control} 控制)",
        "one": "[仿真节点] 关节 {index} 目标 → {angle:g}°",
        "all": "[仿真节点] 全关节目标 → {angles}°",
        "clamped": "[仿真节点] 超出关节限位: {note}",
        "rejected": "[仿真节点] 忽略无效 joint_cmd: {error}",
        "no_timer": "[仿真节点] tick 不是 dora 定时器,物理步长取 {step_ms:g} ms",
        "window_closed": "[仿真节点] 仿真停止: {reason}",
    },
    "en": {
        "loaded": "[simulation] SO-101 loaded, robot_id = {robot_id} ({mode} mode, step {step_ms:g} ms, {control} control)",
        "one": "[simulation] joint {index} target -> {angle:g}°",
        "all": "[simulation] all joint targets -> {angles}°",
        "clamped": "[simulation] beyond the joint limits: {note}",
        "rejected": "[simulation] ignored invalid joint_cmd: {error}",
        "no_timer": "[simulation] tick is not a dora timer; physics step set to {step_ms:g} ms",
        "window_closed": "[simulation] stopping: {reason}",
    },
}


def log(line: str) -> None:
    print(line, flush=True)


def _number(environ, name: str, default: str, minimum: float) -> float:
    raw = environ.get(name, default)
    try:
        value = float(raw)
    except ValueError:
        value = float("nan")
    if not value >= minimum:  # also rejects NaN
        raise ValueError(f"{name}={raw!r} is not a number >= {minimum:g}")
    return value


def _whole_number(environ, name: str, default: str) -> int:
    raw = environ.get(name, default)
    if not raw.strip().isdigit():
        raise ValueError(f"{name}={raw!r} is not a whole number >= 0")
    return int(raw)


# In fast mode a tick is made up whenever no input is waiting.
FAST_TICK = {"type": "INPUT", "id": "tick", "value": None, "metadata": {}}


def fast_events(node):
    """The node's events without waiting: FAST_TICK whenever its queue is empty.

    Fast mode polls instead of taking a 0 ms timer: the physics step stays the
    timer's period (a 0 ms tick would make it 0), and no event has to travel
    through the daemon per step.
    """
    while True:
        event = node.try_recv()
        yield FAST_TICK if event is None else event


def main() -> int:
    try:
        mode = os.environ.get("SO101_MODE", "auto")
        control_mode = os.environ.get("SO101_CONTROL", "position")
        servo_zeta = _number(os.environ, "SO101_SERVO_ZETA", "0.7", 0.0)
        image_hz = _number(os.environ, "SO101_IMAGE_HZ", "0", 0.0)
        fast_steps = _whole_number(os.environ, "SO101_FAST_STEPS", "0")
    except ValueError as error:
        print(f"[simulation] cannot start: {error}", file=sys.stderr, flush=True)
        return 2
    text = TEXT["en" if os.environ.get("SO101_LANG", "zh") == "en" else "zh"]

    # Load the arm before joining the dataflow: ticks that arrive while the URDF loads
    # would only be discarded, one warning each.
    release_freed_memory()
    try:
        sim = SO101Sim(
            mode=mode, time_step_s=TICK_PERIOD_S, control_mode=control_mode,
            servo_damping_ratio=servo_zeta, log=log, renders=image_hz > 0,
        )
    except (ModelFilesError, DisplayError, ValueError) as error:
        print(f"[simulation] cannot start: {error}", file=sys.stderr, flush=True)
        return 2
    node = Node()
    # The physics step equals the tick period, so simulated time keeps pace with the
    # wall clock (the course's default 1/240 s step on a 4 ms tick runs 4% fast).
    tick_s = timer_period_s(node.node_config())
    if tick_s is None:
        tick_s = TICK_PERIOD_S
        log(text["no_timer"].format(step_ms=tick_s * 1000))
    sim.set_time_step_s(tick_s)
    log(text["loaded"].format(robot_id=sim.robot_id, mode=sim.mode.upper(), step_ms=tick_s * 1000, control=control_mode))

    joint_targets_deg = tuple(HOME_POSE_DEG)
    events = fast_events(node) if fast_steps else node
    # (start ns, end ns, physics steps so far) of each tick, in time.monotonic_ns, when asked for;
    # None costs nothing per tick.
    tick_log_path = os.environ.get("SO101_TICK_LOG", "")
    tick_log = array("q") if tick_log_path else None
    tick_clock = TickClock(tick_s)
    # Counted in physics steps, so fast mode (several steps per tick) keeps the simulated rate.
    steps_per_image = max(1, round(1.0 / (image_hz * tick_s))) if image_hz > 0 else 0
    next_image_step = steps_per_image
    try:
        for event in events:
            if event["type"] == "INPUT":
                if event["id"] == "tick":
                    if tick_log is not None:
                        tick_log.append(time.monotonic_ns())
                    if fast_steps:
                        sim.step(fast_steps)
                    else:
                        sim.step(tick_clock.steps_due(event["metadata"].get("timestamp")))
                    angles_deg = sim.joint_angles_deg()
                    node.send_output("joint_state", pa.array(angles_deg[:NUM_ARM_JOINTS], type=pa.float64()))
                    node.send_output("gripper_state", pa.array(angles_deg[NUM_ARM_JOINTS:], type=pa.float64()))
                    if tick_log is not None:
                        tick_log.extend((time.monotonic_ns(), sim.steps))
                    if steps_per_image and sim.steps >= next_image_step:
                        next_image_step += steps_per_image * ((sim.steps - next_image_step) // steps_per_image + 1)
                        width, height = IMAGE_SIZE
                        rgb = sim.render_rgb(width, height)
                        node.send_output(
                            "image", pa.array(rgb.ravel()),
                            {"width": width, "height": height, "encoding": "rgb8"},
                        )
                elif event["id"] == "joint_cmd":
                    decoded = decode_joint_cmd(event["value"], joint_targets_deg)
                    if decoded.error:
                        log(text["rejected"].format(error=decoded.error))
                        continue
                    for note in decoded.notes:
                        log(text["clamped"].format(note=note))
                    previous_gripper_deg = joint_targets_deg[GRIPPER_COMMAND_INDEX]
                    joint_targets_deg = decoded.targets_deg
                    sim.set_targets_deg(joint_targets_deg)
                    if decoded.joint_index is not None:
                        log(text["one"].format(index=decoded.joint_index, angle=joint_targets_deg[decoded.joint_index]))
                    else:
                        log(text["all"].format(angles=[round(a, 2) for a in joint_targets_deg[:NUM_ARM_JOINTS]]))
                        if joint_targets_deg[GRIPPER_COMMAND_INDEX] != previous_gripper_deg:
                            log(text["one"].format(index=GRIPPER_COMMAND_INDEX, angle=joint_targets_deg[GRIPPER_COMMAND_INDEX]))
            elif event["type"] == "STOP":
                break
    except KeyboardInterrupt:
        pass  # Ctrl-C on a node run by hand: stop like STOP
    except WindowClosed as closed:
        # As in the course, closing the window ends the simulation; exit code 1 makes dora
        # stop the dataflow and say so, rather than leave a prompt driving nothing.
        print(text["window_closed"].format(reason=closed), file=sys.stderr, flush=True)
        return 1
    finally:
        sim.close()
        if tick_log is not None:
            with open(tick_log_path, "wb") as tick_log_file:
                tick_log.tofile(tick_log_file)
    return 0


if __name__ == "__main__":
    sys.exit(main())
