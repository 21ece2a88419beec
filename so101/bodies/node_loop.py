"""One dora event loop for any body of the SO-101 (PyBullet, MuJoCo, the real arm): the node's contract.

A body is what so101.bodies.protocol.Body describes. This loop turns one into the node
dataflow.yml declares: each `tick` advances the physics by the tick's period (and the
periods of ticks dora dropped while the node was late) and publishes `joint_state` and
`gripper_state`; a `joint_cmd` is decoded, clamped to the joint limits and logged, and only
updates the targets, which the next tick applies; bad ones are logged and ignored (a stream of
commands, marked so in their metadata, is not logged command by command). Where the
dataflow declares a `joint_target` output (`so101 teleop --record` does, for the recorder), the
targets the body applies go out on it at the first tick, whenever they change, and once a second
for a node that joined late. A body running a task (handed to it: so101.bodies.protocol.SceneTask) also publishes, where the
dataflow declares them, `object_state` each tick (float32, the task's object names in its
metadata) and `task_status` (the success function's answer, a bool, with the task and seed in its
metadata) at the first tick, whenever it changes, after each reset and once a second; a
`task_cmd` (`reset` or `reset SEED`) lays the scene out again and homes the arm (TaskReport).
In lockstep (SO101_LOCKSTEP_FPS, so101/runtime/lockstep.py) there is no tick: each `joint_cmd`
tagged for the frame now steps one frame and the next frame goes out, with the task's pictures
where asked; a reset starts the next episode; the node ends when its `task_cmd` closes.
STOP or Ctrl-C closes the body and ends with 0, as every node's loop does
(so101/runtime/node_events.py). The real arm differs only where hardware must: it
starts from where it stands (`start_targets_deg`), a tick whose read failed publishes
nothing (`joint_angles_deg` is None), and a bus past saving ends the node with one line and
exit code 1 (BodyFailed).

The loop's settings (display mode, image rate, fast mode, tick log, language) are
so101.bodies.settings.NodeSettings.
"""

from __future__ import annotations

import logging
import sys
import time
from array import array
from typing import TYPE_CHECKING, Iterable, Iterator, Mapping, Protocol, cast

import numpy as np
import pyarrow as pa

from so101.bodies.protocol import AnglesDeg, Body, BodyFailed, RgbImage, TaskScene
from so101.bodies.settings import NodeSettings
from so101.bodies.task_cameras import IMAGE_SIZE
from so101.joint_cmd import decode_joint_cmd
from so101.robot import GRIPPER_COMMAND_INDEX, NUM_ARM_JOINTS
from so101.runtime.dataflow import TICK_PERIOD_S, TickClock, timer_period_s
from so101.runtime.lockstep import AGAIN_WORD, FrameTag, answers, frame_tag, steps_per_frame
from so101.runtime.node_events import STREAM_KEY, Event, cannot_start, inputs_until_stop, until_closed
from so101.task_cmd import parse_reset

if TYPE_CHECKING:
    from dora import Node

    from so101.bodies.task_cameras import TaskCameras

# `joint_target` goes out again this often even when unchanged, for a node that joined late.
TARGET_REFRESH_S = 1.0

# Each body node's log tag: the simulation's, or the real arm's (node id `arm`).
TAGS = {
    "simulation": {"zh": "[仿真节点]", "en": "[simulation]"},
    "arm": {"zh": "[机械臂节点]", "en": "[arm]"},
}

TEXT = {
    "zh": {
        "loaded": "{tag} SO-101 加载完成,{identity}({mode} 模式,步长 {step_ms:g} ms,{detail})",
        "one": "{tag} 关节 {index} 目标 → {angle:g}°",
        "all": "{tag} 全关节目标 → {angles}°",
        "clamped": "{tag} 超出关节限位: {note}",
        "rejected": "{tag} 忽略无效 joint_cmd: {error}",
        "no_timer": "{tag} tick 不是 dora 定时器,物理步长取 {step_ms:g} ms",
        "stopping": "{tag} 停止: {reason}",
        "laid_out": "{tag} 任务 {task}: 按种子 {seed} 摆放,机械臂回零位",
        "succeeded": "{tag} 任务 {task}: 方块已在盒中(种子 {seed})",
        "bad_task_cmd": "{tag} 忽略无效 task_cmd: {error}",
    },
    "en": {
        "loaded": "{tag} SO-101 loaded, {identity} ({mode} mode, step {step_ms:g} ms, {detail})",
        "one": "{tag} joint {index} target -> {angle:g}°",
        "all": "{tag} all joint targets -> {angles}°",
        "clamped": "{tag} beyond the joint limits: {note}",
        "rejected": "{tag} ignored invalid joint_cmd: {error}",
        "no_timer": "{tag} tick is not a dora timer; physics step set to {step_ms:g} ms",
        "stopping": "{tag} stopping: {reason}",
        "laid_out": "{tag} task {task}: laid out from seed {seed}, the arm at home",
        "succeeded": "{tag} task {task}: the cube is in the box (seed {seed})",
        "bad_task_cmd": "{tag} ignored invalid task_cmd: {error}",
    },
}


logger = logging.getLogger(__name__)


def announce(line: str) -> None:
    """A line that tools wait for and parse (the "loaded" line, the window's): stdout, as it is, at once."""
    print(line, flush=True)


# In fast mode a tick is made up whenever no input is waiting.
FAST_TICK: Event = {"type": "INPUT", "id": "tick", "value": None, "metadata": {}}


class Polled(Protocol):
    """A node whose queue can be read without waiting."""

    def try_recv(self) -> Event | None: ...


def fast_events(node: Polled) -> Iterator[Event]:
    """The node's events without waiting: FAST_TICK whenever its queue is empty.

    Fast mode polls instead of taking a 0 ms timer: the physics step stays the
    timer's period (a 0 ms tick would make it 0), and no event has to travel
    through the daemon per step.
    """
    while True:
        event = node.try_recv()
        yield FAST_TICK if event is None else event


class TaskReport:
    """A task's outputs (where the dataflow declares them): `object_state` each tick, `task_status` at
    the first tick, whenever success changes, after a reset (answering its request) and every
    `refresh_steps` for a node that joined late."""

    def __init__(self, scene: TaskScene, outputs: Iterable[str], refresh_steps: int, text: Mapping[str, str]):
        self.scene, self.refresh_steps, self.text = scene, refresh_steps, text
        self.sends_objects = "object_state" in outputs
        self.sends_status = "task_status" in outputs
        self.object_names = ",".join(scene.task.object_state_names)
        self.last_success: bool | None = None  # None: task_status is due at the next tick
        self.reply_to = ""  # the task_cmd request the next task_status answers
        self.status_sent_at_step = 0

    def tick(self, node: Node, steps: int, tag: FrameTag | None = None) -> bool:
        """`tag`: a lockstep frame's, on both outputs; task_status then goes out every frame.
        Returns whether the task has succeeded."""
        scene = self.scene
        object_state = scene.object_state()  # read once a tick: published, and judged
        tags = tag.metadata() if tag is not None else {}
        if self.sends_objects:
            node.send_output("object_state", pa.array(object_state), {"names": self.object_names, **tags})
        success = scene.task.state_succeeded(object_state, scene.cube_speed_m_s())
        if success and success != self.last_success and tag is None:  # in lockstep the episodes' runner says it
            logger.info(self.text["succeeded"].format(task=scene.task.name, seed=scene.layout.seed))
        if self.sends_status and (success != self.last_success or tag is not None
                                  or steps - self.status_sent_at_step >= self.refresh_steps):
            node.send_output("task_status", pa.array([success]),
                             {"task": scene.task.name, "seed": scene.layout.seed, "reply_to": self.reply_to, **tags})
            self.status_sent_at_step = steps
        self.last_success, self.reply_to = success, ""
        return success

    def seed_asked(self, words: list[object]) -> int:
        """The seed a task_cmd asks for: the one it names, or the next; ValueError in one line otherwise."""
        asked = parse_reset(" ".join(str(word) for word in words))
        return self.scene.layout.seed + 1 if asked is None else asked

    def laid_out(self, seed: int, request: str) -> None:
        """After a reset: the next tick's task_status answers `request`."""
        self.last_success, self.reply_to = None, request
        logger.info(self.text["laid_out"].format(task=self.scene.task.name, seed=seed))


def run_body_node(body: Body, node: Node, settings: NodeSettings, identity: str, detail: Mapping[str, str],
                  node_id: str = "simulation", cameras: TaskCameras | None = None) -> int:
    """The event loop, until STOP; closes `body` (and `cameras`). `identity` and `detail[lang]` go into the
    "loaded" log line (`so101 teleop` waits for it). `cameras` draw the `image` output's pictures and a
    lockstep frame's (so101.bodies.task_cameras.node_cameras). Returns the node's exit code."""
    tag = TAGS[node_id][settings.lang]
    text = {key: line.replace("{tag}", tag) for key, line in TEXT[settings.lang].items()}
    fast_steps = settings.fast_steps
    image_hz = settings.image_hz
    # The physics step equals the tick period, so simulated time keeps pace with the
    # wall clock (the course's default 1/240 s step on a 4 ms tick runs 4% fast).
    lockstep_fps = settings.lockstep_fps
    if lockstep_fps and body.kind == "real":
        body.close()
        return cannot_start(ValueError("SO101_LOCKSTEP_FPS: the real arm keeps the wall clock's time; lockstep is "
                                       "for the simulations"), node_id)
    tick_s = TICK_PERIOD_S if lockstep_fps else timer_period_s(node.node_config())
    if tick_s is None:
        tick_s = TICK_PERIOD_S
        logger.warning(text["no_timer"].format(step_ms=tick_s * 1000))
    body.set_time_step_s(tick_s)
    # GUI or DIRECT: where the arm is seen; hardware has no display and says REAL.
    shown_mode = (body.display_mode or body.kind).upper()
    announce(text["loaded"].format(identity=identity, mode=shown_mode, step_ms=tick_s * 1000, detail=detail[settings.lang]))

    # A simulation starts at home; the real arm where it stands, so a one-joint command moves one joint.
    joint_targets_deg = body.start_targets_deg()
    # pyarrow's first array from numpy takes about 12 ms: paid here, before the ticks come, the first
    # tick is as quick as the rest, and no tick is dropped meanwhile (dora warns once for each).
    pa.array(np.zeros(NUM_ARM_JOINTS), type=pa.float64())
    # dora's type stubs (1.1.0) lack try_recv, which its Node has. In lockstep the episodes' runner
    # ends the node by going away: its task_cmd closes.
    events: Iterable[Event] = (fast_events(cast(Polled, node)) if fast_steps
                               else until_closed(node, "task_cmd") if lockstep_fps else node)
    # (start ns, end ns, physics steps so far) of each tick, in time.monotonic_ns, when asked for;
    # None costs nothing per tick. In lockstep, of each frame answered: (its first part going out the first
    # time, the joint_cmd that answers it in, its episode: resets so far), the driver's round trip, a loss and
    # the runner's `again` included (so101 bench --round-trip); episode 0 is the body's start, before any reset.
    tick_log: array[int] | None = array("q") if settings.tick_log_path else None
    tick_clock = TickClock(tick_s)
    # Counted in physics steps, so fast mode (several steps per tick) keeps the simulated rate.
    steps_per_image = max(1, round(1.0 / (image_hz * tick_s))) if image_hz > 0 else 0
    next_image_step = steps_per_image
    outputs = (node.node_config() or {}).get("outputs", [])
    sends_targets = "joint_target" in outputs
    targets_sent_at_step: int | None = None  # body.steps when joint_target last went out; None: to send
    target_refresh_steps = max(1, round(TARGET_REFRESH_S / tick_s))
    scene = body.scene
    report = TaskReport(scene, outputs, target_refresh_steps, text) if scene is not None else None
    # Lockstep: the frame now (episode: resets so far), the steps a frame takes, the pictures it carries.
    frame_steps = steps_per_frame(lockstep_fps, tick_s) if lockstep_fps else 0
    now = FrameTag(0, 0, scene.layout.seed if scene is not None else 0)
    # In lockstep, an episode over (success, or its last frame) holds still until a reset: every
    # episode then ends at the same frame, however late the runner's reset comes.
    episode_over = False
    frame_out: tuple[FrameTag | None, int] = (None, 0)  # in lockstep: the frame now, when it began to go out (ns)

    def pictures(angles_deg: AnglesDeg, width: int, height: int, wrist: bool) -> tuple[RgbImage, RgbImage | None]:
        """The body as it stands, drawn by `cameras` (front, and the wrist's where asked and a task has it)."""
        assert cameras is not None
        return cameras.draw(angles_deg, scene.object_state() if scene is not None else [], width, height, wrist)

    def publish(tag: FrameTag | None = None) -> None:
        """joint_state and gripper_state, the task's outputs, and in lockstep the frame's pictures."""
        nonlocal episode_over, frame_out
        if tag is not None and tag != frame_out[0]:  # the first time (not `again`'s)
            frame_out = (tag, time.monotonic_ns())
        tags = tag.metadata() if tag is not None else {}
        angles_deg = body.joint_angles_deg()
        # None: the real arm's read failed this tick; publishing nothing beats stale angles.
        if angles_deg is not None:
            node.send_output("joint_state", pa.array(angles_deg[:NUM_ARM_JOINTS], type=pa.float64()), tags)
            node.send_output("gripper_state", pa.array(angles_deg[NUM_ARM_JOINTS:], type=pa.float64()), tags)
        success = report.tick(node, body.steps, tag) if report is not None else False
        if tag is not None and settings.lockstep_episode_frames:
            episode_over = success or tag.frame >= settings.lockstep_episode_frames
        if tag is not None and settings.lockstep_pictures and cameras is not None and angles_deg is not None:
            width, height = settings.lockstep_pictures
            front, wrist = pictures(angles_deg, width, height, "wrist_image" in outputs)
            for output, rgb in (("image", front), ("wrist_image", wrist)):
                if rgb is not None and output in outputs:
                    node.send_output(output, pa.array(rgb.ravel()),
                                     {"width": width, "height": height, "encoding": "rgb8", **tags})

    def finish() -> None:  # however the loop ends: the window, the bus let go; the tick log kept
        body.close()
        if cameras is not None:
            cameras.close()
        if tick_log is not None:
            with open(settings.tick_log_path, "wb") as tick_log_file:
                tick_log.tofile(tick_log_file)

    with inputs_until_stop(events, close=finish) as inputs:
        try:
            if lockstep_fps:
                publish(now)  # the first frame: the driver's first action answers it
            for event in inputs:
                if event["id"] == "tick" and lockstep_fps:
                    continue
                if event["id"] == "tick":
                    if tick_log is not None:
                        tick_log.append(time.monotonic_ns())
                    if fast_steps:
                        body.step(fast_steps)
                    else:
                        body.step(tick_clock.steps_due(event["metadata"].get("timestamp")))
                    if sends_targets and (targets_sent_at_step is None
                                          or body.steps - targets_sent_at_step >= target_refresh_steps):
                        node.send_output("joint_target", pa.array(joint_targets_deg, type=pa.float64()))
                        targets_sent_at_step = body.steps
                    publish()
                    if tick_log is not None:
                        tick_log.extend((time.monotonic_ns(), body.steps))
                    if steps_per_image and cameras is not None and body.steps >= next_image_step:
                        next_image_step += steps_per_image * ((body.steps - next_image_step) // steps_per_image + 1)
                        width, height = IMAGE_SIZE
                        angles_deg = body.joint_angles_deg()
                        if angles_deg is None:
                            continue
                        rgb, _ = pictures(angles_deg, width, height, wrist=False)
                        node.send_output(
                            "image", pa.array(rgb.ravel()),
                            {"width": width, "height": height, "encoding": "rgb8"},
                        )
                elif event["id"] == "task_cmd" and lockstep_fps and event["value"].to_pylist() == [AGAIN_WORD]:
                    publish(now)  # a receiver lost part of this frame
                elif event["id"] == "task_cmd":
                    try:
                        if report is None:
                            raise ValueError("this body runs no task")
                        seed = report.seed_asked(event["value"].to_pylist())
                        body.reset_task(seed)
                        if cameras is not None:
                            cameras.show_seed(seed)  # the episode's looks, where they vary
                    except ValueError as error:
                        logger.warning(text["bad_task_cmd"].format(error=error))
                        continue
                    joint_targets_deg = body.start_targets_deg()
                    targets_sent_at_step = None
                    report.laid_out(seed, str((event.get("metadata") or {}).get("request", "")))
                    if lockstep_fps:
                        now = FrameTag(now.episode + 1, 0, seed)
                        publish(now)
                elif event["id"] == "joint_cmd":
                    if lockstep_fps and (episode_over or not answers(frame_tag(event.get("metadata")), now)):
                        continue  # sent for a frame before a reset, or past the episode's end: it is over
                    if lockstep_fps and tick_log is not None:
                        tick_log.extend((frame_out[1], time.monotonic_ns(), now.episode))
                    decoded = decode_joint_cmd(event["value"], joint_targets_deg)
                    if decoded.targets_deg is None:  # what arrived is not a command: decoded.error says why
                        logger.warning(text["rejected"].format(error=decoded.error))
                        continue
                    previous_gripper_deg = joint_targets_deg[GRIPPER_COMMAND_INDEX]
                    joint_targets_deg = decoded.targets_deg
                    body.set_targets_deg(joint_targets_deg)
                    targets_sent_at_step = None
                    if lockstep_fps:  # the action of this frame, then the next frame
                        if sends_targets:
                            node.send_output("joint_target", pa.array(joint_targets_deg, type=pa.float64()), now.metadata())
                        body.step(frame_steps)
                        now = FrameTag(now.episode, now.frame + 1, now.seed)
                        publish(now)
                        continue
                    if STREAM_KEY in (event.get("metadata") or {}):
                        continue  # one command a tick (the leader's): a log line each would bury the log
                    for note in decoded.notes:
                        logger.warning(text["clamped"].format(note=note))
                    if decoded.joint_index is not None:
                        logger.info(text["one"].format(index=decoded.joint_index, angle=joint_targets_deg[decoded.joint_index]))
                    else:
                        logger.info(text["all"].format(angles=[round(a, 2) for a in joint_targets_deg[:NUM_ARM_JOINTS]]))
                        if joint_targets_deg[GRIPPER_COMMAND_INDEX] != previous_gripper_deg:
                            logger.info(text["one"].format(index=GRIPPER_COMMAND_INDEX, angle=joint_targets_deg[GRIPPER_COMMAND_INDEX]))
        except BodyFailed as failure:
            # Closing the window ends the simulation, as in the course; the real arm's bus past its
            # retries ends the driver. Exit code 1 makes dora stop the dataflow and say so, rather
            # than leave a prompt driving nothing. Said before the body closes (its close may log).
            print(text["stopping"].format(reason=failure), file=sys.stderr, flush=True)
            return 1
    return 0

