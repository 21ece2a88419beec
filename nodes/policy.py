"""policy: a trained LeRobot policy, a sender of `joint_cmd` like the expert, the prompt or the leader.

It runs under the Python of a policy environment (`so101 policy-env`; `--policy-python`), and
imports only dora-rs, pyarrow, numpy, LeRobot and this project's plain modules (no simulator).
At start it loads SO101_POLICY_DIR as LeRobot's `lerobot-train` writes it (config, weights,
pre- and post-processors) with LeRobot's factory, so any policy type LeRobot knows loads, and
it takes the inputs its input features ask for: `observation.state` from `joint_state` and
`gripper_state`, `observation.environment_state` from `object_state`, the cameras from `image`
and `wrist_image`. A feature the dataflow cannot give refuses the node in one line that names it.
In lockstep (`so101 eval --policy`; so101/runtime/lockstep.py), once a frame's parts are in, it
answers that frame with six joint targets, tagged with it, in the body's units (mapped where the
recorder maps them: so101/policy/features.py); a frame 0 is a new episode and resets the policy
(an action chunk is played out across the frames that follow, as LeRobot's `select_action` does).
A frame sent again gets the same answer. Inference that raises stops the node in one line; the
body then holds where it is (in lockstep it steps only on an answer).
At the prompt (`so101 teleop --policy`) it stands between the prompt and the body, as the expert
does: what comes before it (`typed_cmd`) goes on to the body as it is; `policy_cmd` `on` resets
the policy and has it drive, an action every `tick` (the dataset's 40 ms) from the newest state,
until `off`, a typed command takes over, inference fails, or a real camera it sees (SO101_POLICY_CAMERAS)
has sent no picture for CAMERA_SILENT_S, the recorder's rule (one line of news; the node stays, and
typed commands still pass), and then says what its inference cost while it drove (chunks, median and
longest time). Stopped by a camera, it acts on no stale picture: the arm holds its last targets, as after
`off`, and `on` is refused until the camera sends again. A tick that comes while it infers is dropped, not queued: the body holds the last
targets meanwhile, and the next chunk starts from the newest state. Its news goes out on `policy_status`. The body's limits and ramps
apply to its commands as to typed ones.
Settings: so101.policy.settings.PolicySettings.
"""

from __future__ import annotations

import logging
import os
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere: the so101 package sits beside nodes/
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
import pyarrow as pa  # noqa: E402
from dora import Node  # noqa: E402

from so101.cameras.sources import silent_camera  # noqa: E402
from so101.policy.features import inputs_for, joint_targets_deg, observation  # noqa: E402
from so101.policy.loaded import LoadedPolicy, PolicyFailed  # noqa: E402
from so101.policy.settings import PolicySettings  # noqa: E402
from so101.runtime.dataflow import PICTURE_OF_CAMERA  # noqa: E402
from so101.runtime.lockstep import INFERENCE_MS_KEY, FrameParts, FrameTag, LastAnswer, frame_tag  # noqa: E402
from so101.runtime.logs import send_diagnostics_to  # noqa: E402
from so101.runtime.node_events import STREAM_KEY, cannot_start, inputs_until_stop  # noqa: E402
from so101.tasks import task_named  # noqa: E402

NODE_ID = "policy"
logger = logging.getLogger("so101.policy")

TEXT = {
    "zh": {
        "loaded": "[策略] {kind} 策略已加载({folder}),读取 {inputs}",
        "driving": "[策略] {kind} 开始驾驶;键入任何动作命令即接管,policy off 停下",
        "stopped": "[策略] 停下了",
        "took_over": "[策略] 键入的命令接管了控制,策略停下",
        "no_state": "[策略] 还没有收到 {inputs}:没有开始",
        "failed": "[策略] 推理失败,策略停下:{error}",
        "camera_lost": "[策略] {camera} 相机 {seconds:.1f} 秒没有画面:策略停下,机械臂保持不动;画面恢复后再 policy on",
        "camera_silent": "[策略] {camera} 相机已有 {seconds:.1f} 秒没有画面:没有开始(插好了吗?)",
        "timing": "[策略] 这次驾驶推理了 {chunks} 个动作块:中位 {median:.0f} 毫秒,最长 {longest:.0f} 毫秒({device})",
    },
    "en": {
        "loaded": "[policy] {kind} policy loaded from {folder}: it reads {inputs}",
        "driving": "[policy] {kind} is driving: any move you type takes over; policy off stops it",
        "stopped": "[policy] stopped",
        "took_over": "[policy] a typed command took over: the policy stopped",
        "no_state": "[policy] no {inputs} yet: not started",
        "failed": "[policy] inference failed, the policy stopped: {error}",
        "camera_lost": "[policy] the {camera} camera sent no picture for {seconds:.1f} s: the policy stopped, the arm "
                       "holds; policy on once its pictures are back",
        "camera_silent": "[policy] the {camera} camera has sent no picture for {seconds:.1f} s: not started "
                         "(is it plugged in?)",
        "timing": "[policy] this drive inferred {chunks} action chunks: median {median:.0f} ms, longest {longest:.0f} ms "
                  "({device})",
    },
}


def main() -> int:
    send_diagnostics_to("stdout")
    try:
        settings = PolicySettings.from_environ(os.environ)
        task = task_named(settings.task)
        loaded = LoadedPolicy(settings.policy_dir, settings.device, task.instruction, settings.threads)
        needed = inputs_for(loaded.input_shapes, loaded.output_shapes, task.object_state_names, settings.image_size)
    except (ValueError, PolicyFailed) as error:
        return cannot_start(error, NODE_ID)
    text = TEXT[settings.lang]
    # so101 teleop waits for this line (so101.runtime.dataflow.POLICY_READY_MARKS).
    logger.warning(text["loaded"].format(kind=loaded.kind, folder=settings.policy_dir, inputs=", ".join(needed)))
    frames = FrameParts(needed)
    episode: int | None = None  # lockstep: the episode the policy's history belongs to
    answered: LastAnswer[tuple[list[float], dict[str, float]]] = LastAnswer()  # lockstep
    latest: dict[str, Any] = {}  # at the prompt: the newest of each input the policy needs
    driving = False  # at the prompt: `on` came, and nothing has stopped it since
    # The real cameras it sees, by their picture input (its own, or its eyes': a seeing recipe's policy takes
    # the front picture only to watch it); when each one's newest picture came (monotonic).
    watched = {PICTURE_OF_CAMERA[name]: name for name in settings.real_cameras}
    arrived_s: dict[str, float] = {}

    def silent() -> tuple[str, float] | None:
        return silent_camera(arrived_s, watched.values(), time.monotonic())
    node = Node()

    def say(line: str) -> None:
        logger.warning(line)
        node.send_output("policy_status", pa.array([line]))

    drive_ms: list[float] = []  # at the prompt: each new chunk's inference time since `on`

    def stop(why: str) -> None:
        """The policy stops driving: why, and what its inference cost while it drove (the body held
        its last targets meanwhile: a tick that comes while it infers is dropped, not queued)."""
        nonlocal driving
        driving = False
        say(why)
        if drive_ms:
            say(text["timing"].format(chunks=len(drive_ms), median=float(np.median(drive_ms)), longest=max(drive_ms),
                                      device=settings.device))
        drive_ms.clear()

    def act(frame: dict[str, Any], new_episode: bool = False) -> tuple[list[float], dict[str, float]]:
        """Six targets, and the metadata that says how long a new chunk's inference took."""
        if new_episode:  # the action chunk and any history of the episode before go
            loaded.reset()
        action, inference_ms = loaded.act(observation(frame, settings.image_size))
        return joint_targets_deg(action), {} if inference_ms is None else {INFERENCE_MS_KEY: inference_ms}

    with inputs_until_stop(node, close=lambda: None) as inputs:
        for event in inputs:
            input_id, value = event["id"], event["value"]
            tag = frame_tag(event.get("metadata"))
            if tag is not None:  # lockstep: answer the frame once it is whole
                frame = frames.add(input_id, tag, value.to_numpy(zero_copy_only=False))
                if frame is None:
                    continue
                try:
                    targets_deg, timing = answered.to(
                        tag, lambda: act(frame, new_episode=tag.frame == 0 or tag.episode != episode))
                except Exception as error:  # noqa: BLE001 (inference that raises: one line, and the node stops)
                    print(f"[{NODE_ID}] cannot go on: inference failed at frame {tag.frame} (seed {tag.seed}): "
                          f"{type(error).__name__}: {error}", file=sys.stderr, flush=True)
                    return 1
                episode = tag.episode
                node.send_output("joint_cmd", pa.array(targets_deg, type=pa.float64()),
                                 {**tag.metadata(), STREAM_KEY: 1, **timing})
            elif input_id in needed or input_id in watched:
                if input_id in needed:
                    latest[input_id] = value.to_numpy(zero_copy_only=False)
                if input_id in watched:
                    arrived_s[watched[input_id]] = time.monotonic()
            elif input_id == "typed_cmd":
                node.send_output("joint_cmd", value)
                if driving:
                    stop(text["took_over"])
            elif input_id == "policy_cmd":
                word = (value.to_pylist() or [""])[0]
                if word == "off":
                    if driving:
                        stop(text["stopped"])
                elif word == "on" and (stopped := silent()) is not None:
                    say(text["camera_silent"].format(camera=stopped[0], seconds=stopped[1]))
                elif word == "on" and all(name in latest for name in needed):
                    loaded.reset()
                    drive_ms.clear()
                    driving = True
                    say(text["driving"].format(kind=loaded.kind))
                elif word == "on":
                    say(text["no_state"].format(inputs=", ".join(name for name in needed if name not in latest)))
            elif input_id == "tick" and driving:
                stopped = silent()
                if stopped is not None:  # its newest picture is stale: no action is taken from it
                    stop(text["camera_lost"].format(camera=stopped[0], seconds=stopped[1]))
                    continue
                try:
                    targets_deg, timing = act(latest)
                except Exception as error:  # noqa: BLE001 (at the prompt: the news, and typed commands still pass)
                    stop(text["failed"].format(error=f"{type(error).__name__}: {error}"))
                    continue
                drive_ms.extend(timing.values())
                node.send_output("joint_cmd", pa.array(targets_deg, type=pa.float64()), {STREAM_KEY: NODE_ID})
    return 0


if __name__ == "__main__":
    sys.exit(main())
