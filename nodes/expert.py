"""expert: the scripted expert of a task, a sender of `joint_cmd` like the prompt or the leader.

It reads only `joint_state`, `gripper_state` and `object_state`. In lockstep (`so101 eval`,
`so101 demos`; so101/runtime/lockstep.py), once the three parts of a frame are in, it answers
that frame with six joint targets, tagged with it (a frame sent again gets the same answer). A
frame 0 is a new episode (a reset): a fresh plan for the layout it shows, its noise drawn from
the layout's seed. Its clock is the frame's
index over the frame rate, so the same layout gives the same episode however fast the machine.
While it plays a miss on purpose (SO101_EXPERT_MISSES) its answers say `not_written`: the
runner keeps the recovery that follows, not the miss. With a learner (SO101_EXPERT_LEARNER, DAgger:
`so101 demos --learner`), a trained state policy drives each episode first, its answers not written,
and at a frame drawn from the episode's seed the expert takes over from wherever the learner left the
arm and the cube: what is written is the expert's way on from the states the learner reaches. A seeing
recipe's learner (SO101_EXPERT_LEARNER_SEES) reads `seen_state`, what its eyes found, while the expert
reads the simulator's `object_state`.
At the prompt (`so101 teleop --task`), it stands between the prompt and the body, as the leader
does: what the prompt sends (`typed_cmd`) goes on to the body as it is; `expert_cmd` `run` has it
do the task once from where things are, a target every `tick` (40 ms) by the wall clock, until
its plan ends, a typed command takes over, or `stop` (a reset) comes. Its news goes out on
`expert_status`. What it plans is so101/tasks/expert.py.
Settings: so101.tasks.settings.ExpertSettings (SO101_TASK, SO101_EXPERT_NOISE, SO101_EXPERT_MISSES, SO101_LOCKSTEP_FPS, SO101_LANG).
"""

from __future__ import annotations

import logging
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere: the so101 package sits beside nodes/
    sys.path.insert(0, str(ROOT))

import pyarrow as pa  # noqa: E402
from dora import Node  # noqa: E402

from so101.assets import ModelFilesError  # noqa: E402
from so101.runtime.lockstep import NOT_WRITTEN_KEY, FrameParts, FrameTag, LastAnswer, frame_tag  # noqa: E402
from so101.policy.features import joint_targets_deg, observation  # noqa: E402
from so101.runtime.logs import send_diagnostics_to  # noqa: E402
from so101.runtime.node_events import STREAM_KEY, cannot_start, inputs_until_stop  # noqa: E402
from so101.tasks import task_named  # noqa: E402
from so101.tasks.expert import Expert, Planner, planner_for, takeover_frame  # noqa: E402
from so101.tasks.settings import ExpertSettings  # noqa: E402

NODE_ID = "expert"
logger = logging.getLogger("so101.expert")
OBSERVED = ("joint_state", "gripper_state", "object_state")

TEXT = {
    "zh": {
        "took_over": "[专家] 键入的命令接管了控制,专家停下",
        "finished": "[专家] 做完了:{seconds:.1f} 秒,{attempts} 次抓取",
        "no_state": "[专家] 还没有收到 joint_state、gripper_state 和 object_state:没有开始",
    },
    "en": {
        "took_over": "[expert] a typed command took over: the expert stopped",
        "finished": "[expert] done: {seconds:.1f} s, {attempts} grasp(s)",
        "no_state": "[expert] no joint_state, gripper_state and object_state yet: not started",
    },
}


def load_learner(settings: ExpertSettings):
    """The learner's policy (so101.policy.loaded, in the policy environment's Python) where there is one, else
    None; ValueError in one line for one that cannot load or reads what the expert's frame lacks (pictures)."""
    if settings.learner is None:
        return None
    from so101.policy.features import inputs_for
    from so101.policy.loaded import LoadedPolicy, PolicyFailed

    task = task_named(settings.task)
    try:
        loaded = LoadedPolicy(settings.learner, "cpu", task.instruction, threads=1)
    except PolicyFailed as error:
        raise ValueError(str(error)) from None
    needed = inputs_for(loaded.input_shapes, loaded.output_shapes, task.object_state_names, None)
    if not set(needed) <= set(OBSERVED):
        raise ValueError(f"the learner {settings.learner} reads {', '.join(needed)}: a learner reads the arm and "
                         f"the objects only ({', '.join(OBSERVED)}), as a state policy does")
    return loaded


def main() -> int:
    send_diagnostics_to("stdout")
    try:
        settings = ExpertSettings.from_environ(os.environ)
        planner: Planner = planner_for(task_named(settings.task))
        # The plans' kinematics use MuJoCo's maths: imported now, while the body starts, not in the first episode.
        import so101.bodies.mujoco_model  # noqa: F401
        learner = load_learner(settings)
    except (ValueError, ModelFilesError) as error:
        return cannot_start(error, NODE_ID)
    text = TEXT[settings.lang]
    # behind a seeing recipe's eyes, the learner reads what they found (seen_state), the expert the simulator's truth
    frames = FrameParts((*OBSERVED, "seen_state") if settings.learner_sees else OBSERVED)
    expert: Expert | None = None
    answered: LastAnswer[tuple[tuple[float, ...], bool]] = LastAnswer()  # lockstep: (targets, not written)
    takeover = 0  # lockstep, with a learner: the frame of this episode at which the expert takes over
    latest: dict[str, list[float]] = {}  # at the prompt: the newest of each observed input
    started_s: float | None = None  # at the prompt: when `run` came; None: not driving
    node = Node()

    def answer(tag: FrameTag, frame: dict[str, list[float]]) -> tuple[tuple[float, ...], bool]:
        """`tag`'s six targets, and whether they are not to be written: a frame 0 is a new episode, a fresh plan
        from its seed (with a learner, the learner's first, until the takeover frame drawn from the seed)."""
        nonlocal expert, takeover
        if tag.frame == 0:
            expert = None
            if learner is not None:
                learner.reset()
                takeover = takeover_frame(tag.seed, settings.takeover_s, settings.lockstep_fps)
        if learner is not None and tag.frame < takeover:
            seen = {**frame, "object_state": frame["seen_state"]} if settings.learner_sees else frame
            action, _ = learner.act(observation(seen, None))
            return tuple(joint_targets_deg(action)), True
        if expert is None:
            expert = Expert(planner, noise=settings.noise, seed=tag.seed, misses=settings.misses)
        targets_deg = expert.targets(tag.frame / settings.lockstep_fps, frame["joint_state"] + frame["gripper_state"],
                                     frame["object_state"])
        return targets_deg, expert.rehearsing

    def say(line: str) -> None:
        logger.warning(line)
        node.send_output("expert_status", pa.array([line]))

    with inputs_until_stop(node, close=planner.close) as inputs:
        for event in inputs:
            input_id = event["id"]
            tag = frame_tag(event.get("metadata"))
            if tag is not None:  # lockstep: answer the frame once it is whole
                frame = frames.add(input_id, tag, event["value"].to_pylist())
                if frame is None:
                    continue
                targets_deg, not_written = answered.to(tag, lambda: answer(tag, frame))
                node.send_output("joint_cmd", pa.array(targets_deg, type=pa.float64()),
                                 {**tag.metadata(), STREAM_KEY: 1, NOT_WRITTEN_KEY: int(not_written)})
            elif input_id in OBSERVED:
                latest[input_id] = event["value"].to_pylist()
            elif input_id == "typed_cmd":
                node.send_output("joint_cmd", event["value"])
                if started_s is not None:
                    started_s = None
                    say(text["took_over"])
            elif input_id == "expert_cmd":
                words = event["value"].to_pylist()
                if words[:1] == ["stop"]:
                    started_s = None
                elif words[:1] == ["run"] and all(name in latest for name in OBSERVED):
                    expert, started_s = Expert(planner, noise=settings.noise), time.monotonic()
                elif words[:1] == ["run"]:
                    say(text["no_state"])
            elif input_id == "tick" and started_s is not None and expert is not None:
                elapsed_s = time.monotonic() - started_s
                targets_deg = expert.targets(elapsed_s, latest["joint_state"] + latest["gripper_state"],
                                             latest["object_state"])
                node.send_output("joint_cmd", pa.array(targets_deg, type=pa.float64()), {STREAM_KEY: NODE_ID})
                if expert.done:
                    started_s = None
                    say(text["finished"].format(seconds=elapsed_s, attempts=expert.attempts))
    return 0


if __name__ == "__main__":
    sys.exit(main())
