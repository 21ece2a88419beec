"""episodes: runs a task's episodes on a body in lockstep, one seed after another, and judges each.

It watches the loop of a driver (the expert, a policy) and a body, as an environment's recorder
does: it lays each episode out (`task_cmd`: `reset SEED`), and at each frame takes the body's frame
(`joint_state`, `gripper_state`, `object_state`, `task_status`, and the pictures where there
are) and the driver's answer to it (`action`), writes the frame into the dataset (SO101_RECORD_DIR,
or a spool for `so101 demos --workers` to merge: SO101_SPOOL_DIR) unless the answer says
`not_written` (the expert's miss on purpose: the episode written starts at its recovery; one with
nothing written is not kept), and ends the episode at the
first frame whose task_status says success, or at the time limit, by laying the next one out.
The driver answers the body directly, so this node's work (writing, encoding) is off the loop's
path; the body holds still after an episode's end until the reset (SO101_EPISODE_FRAMES), so every
episode ends at the same frame however far behind this node is. `SO101_IDLE=1` has no driver: this
node answers every frame with home, the floor every score must beat. Episodes end in order; each
one's outcome is a JSON line in SO101_EPISODES_OUT, and `"done"` after the last, which ends the
node, and with it the body (its task_cmd closes). Episode i uses seed SO101_SEED + i. After
SILENCE_S with nothing come, a message was lost: it asks the body for the frame again (`task_cmd`
`again`), or for the reset again; a frame it never got whole while the body went on has the
episode run again from its layout (the same seed gives the same episode). An episode that cannot
be saved (a full disk) stops the run in one line.
What it judges and scores is so101/tasks/episodes.py.
Settings: so101.tasks.settings.EpisodeSettings.
"""

from __future__ import annotations

import logging
import os
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere: the so101 package sits beside nodes/
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
import pyarrow as pa  # noqa: E402
from dora import Node  # noqa: E402

from so101.dataset.episode import EpisodeRecorder  # noqa: E402
from so101.runtime.node_events import STREAM_KEY, cannot_start  # noqa: E402
from so101.dataset.features import (  # noqa: E402
    ACTION_KEY, ENVIRONMENT_KEY, IMAGE_KEY, REWARD_KEY, STATE_KEY, SUCCESS_KEY, WRIST_IMAGE_KEY, to_lerobot,
    video_keys_and_sizes,
)
from so101.dataset.commit import one_line_os_error  # noqa: E402
from so101.dataset.layout import DatasetError  # noqa: E402
from so101.dataset.spool import EpisodeSpool  # noqa: E402
from so101.dataset.video import StreamingEncoder  # noqa: E402
from so101.dataset.writer import DatasetWriter  # noqa: E402
from so101.robot import HOME_POSE_DEG  # noqa: E402
from so101.runtime.lockstep import (  # noqa: E402
    AGAIN_WORD, INFERENCE_MS_KEY, NOT_WRITTEN_KEY, FrameParts, FrameTag, frame_tag,
)
from so101.runtime.logs import send_diagnostics_to  # noqa: E402
from so101.tasks import task_named  # noqa: E402
from so101.tasks.episodes import EpisodeClock, Outcome, seeds_for  # noqa: E402
from so101.tasks.settings import EpisodeSettings  # noqa: E402

NODE_ID = "episodes"
logger = logging.getLogger("so101.episodes")
# After this long without a message, one was lost (a frame takes milliseconds; the expert's first
# plan, with its kinematics starting, about a second): the runner asks for it again.
SILENCE_S = 3.0


class CannotGoOn(Exception):
    """The run cannot go on (an episode could not be saved); str() is one line for the user."""


def picture(value: Any, size: tuple[int, int]) -> np.ndarray:
    width, height = size
    return value.to_numpy(zero_copy_only=False).astype(np.uint8, copy=False).reshape(height, width, 3)


def main() -> int:
    send_diagnostics_to("stdout")
    try:
        settings = EpisodeSettings.from_environ(os.environ)
        task = task_named(settings.task)
        observed = settings.observed
        video_sizes = video_keys_and_sizes(settings.image_size, True, observed)
        writer: DatasetWriter | EpisodeSpool | None = None
        if settings.record_dir:
            writer = DatasetWriter.open(settings.record_dir, settings.lockstep_fps, video_sizes,
                                        environment_names=task.object_state_names, environment_state=observed.environment)
        elif settings.spool_dir:
            writer = EpisodeSpool(settings.spool_dir, settings.lockstep_fps, video_sizes, task.object_state_names,
                                  observed.environment)
        if settings.video_dir is not None:
            settings.video_dir.mkdir(parents=True, exist_ok=True)
        results = open(settings.results_path, "a", encoding="utf-8")
    except (ValueError, DatasetError, OSError) as error:
        return cannot_start(error, NODE_ID)
    idle = settings.idle
    # The pictures it waits for: those written, and the front one for --video's mp4s.
    written = {"image": IMAGE_KEY in video_sizes, "wrist_image": WRIST_IMAGE_KEY in video_sizes}
    recorded = tuple(name for name, input_id in (("front", "image"), ("wrist", "wrist_image")) if written[input_id])
    pictures = tuple(input_id for input_id in ("image", "wrist_image") if settings.image_size and (
        (writer is not None and written[input_id]) or (input_id == "image" and settings.video_dir is not None)))
    observation = ("joint_state", "gripper_state", "object_state", "task_status", *pictures,
                   *(("seen_state",) if settings.environment_seen else ()))
    # what the policy trained on these frames will read: the eyes' findings (DAgger behind the eyes), or the simulator's
    environment_input = "seen_state" if settings.environment_seen else "object_state"
    frames = FrameParts(observation if idle else (*observation, "action"))
    clock = EpisodeClock(settings.lockstep_fps, settings.time_limit_s)
    seeds = seeds_for(settings.first_seed, settings.episodes)
    node = Node()
    index = 0  # the episode running: seeds[index]
    adopted = 0  # the body's number of the episode running; its start's (0) is never one of ours
    adopted_index = -1  # the index of the episode `adopted` is
    recorder: EpisodeRecorder | None = None
    video: StreamingEncoder | None = None
    answered: list[float] | None = None  # idle: the action of the last frame answered (next_frame - 1)
    next_frame = 0  # the adopted episode's next frame to record
    whole: dict[int, tuple[FrameTag, dict[str, Any]]] = {}  # frames come whole ahead of next_frame
    not_written: set[int] = set()  # the adopted episode's frames whose action the driver said not to write
    inferred_ms: dict[int, float] = {}  # the adopted episode's frames a policy took a new chunk at: how long it took

    def lay_out() -> None:
        node.send_output("task_cmd", pa.array([f"reset {seeds[index]}"]))

    def begin(episode: int) -> None:
        """The body's episode `episode` is seeds[index] laid out: its frames are this run's."""
        nonlocal adopted, adopted_index, recorder, video, answered, next_frame
        drop()
        adopted, adopted_index, answered, next_frame = episode, index, None, 0
        recorder = writer.start_episode(task.instruction) if writer is not None else None
        if recorder is not None:
            recorder.seed = seeds[index]
            # its physics, and with pictures their looks and where its cameras stood: what it showed, and from where
            recorder.scenario = settings.scenario.metadata(seeds[index], recorded if settings.image_size else (),
                                                           settings.image_size)
        if settings.video_dir is not None and settings.image_size:
            width, height = settings.image_size
            video = StreamingEncoder(settings.video_dir / f"seed_{seeds[index]}.mp4",
                                     settings.lockstep_fps, width, height)

    def drop() -> None:
        nonlocal recorder, video
        whole.clear()
        not_written.clear()
        inferred_ms.clear()
        if recorder is not None:
            recorder.discard()
        if video is not None:
            video.cancel()
        recorder = video = None

    def finish(tag: FrameTag, success: bool) -> None:
        """The episode ends at `tag`'s frame."""
        nonlocal index, recorder, video
        whole.clear()
        not_written.clear()
        kept = False
        if recorder is not None:
            saving, recorder = recorder, None
            if saving.frames and (success or settings.keep == "all"):
                try:
                    saving.save()
                except (DatasetError, OSError) as error:  # a full disk: what is saved stays whole; nothing more can be
                    raise CannotGoOn(f"episode {index} (seed {seeds[index]}) could not be saved: {one_line_os_error(error)}"
                                     if isinstance(error, OSError) else f"{error} (seed {seeds[index]})") from None
                kept = True
            else:
                saving.discard()
        if video is not None:
            video.finish()
            video = None
        outcome = Outcome(index, seeds[index], success, tag.frame + 1, clock.seconds(tag.frame), kept=kept,
                          inference_ms=[round(inferred_ms[frame], 2) for frame in sorted(inferred_ms)])
        inferred_ms.clear()
        results.write(outcome.to_json() + "\n")
        results.flush()
        logger.info("[episodes] %s", outcome.line())
        index += 1

    def run_again(lost: int) -> None:
        """A part of frame `lost` never came, and the body went on: the episode again from its layout."""
        nonlocal adopted_index
        logger.info("[episodes] frame %d of episode %d (seed %d) was lost: running it again", lost, index, seeds[index])
        drop()
        adopted_index = -1
        lay_out()

    def take(tag: FrameTag, frame: dict[str, Any]) -> None:
        """Record and judge the adopted episode's next frame; end the episode there, or (idle) answer it."""
        nonlocal answered, next_frame
        state_deg = frame["joint_state"].to_pylist() + frame["gripper_state"].to_pylist()
        action_deg = list(HOME_POSE_DEG) if idle else frame["action"].to_pylist()
        success = bool(frame["task_status"].to_pylist()[0])
        if recorder is not None and tag.frame not in not_written:
            values = {STATE_KEY: to_lerobot(state_deg), ACTION_KEY: to_lerobot(action_deg),
                      SUCCESS_KEY: np.array([success]), REWARD_KEY: np.array([task.reward(success)], dtype=np.float32)}
            if observed.environment:
                values[ENVIRONMENT_KEY] = np.asarray(frame[environment_input].to_numpy(zero_copy_only=False), np.float32)
            for input_id, key in (("image", IMAGE_KEY), ("wrist_image", WRIST_IMAGE_KEY)):
                if written[input_id] and settings.image_size:
                    values[key] = picture(frame[input_id], settings.image_size)
            recorder.add_frame(values)
        if video is not None and settings.image_size:
            video.add(picture(frame["image"], settings.image_size))
        if clock.ended(tag.frame, success):  # the body holds still here until the reset
            finish(tag, success)
            if index < len(seeds):
                lay_out()
            return
        next_frame = tag.frame + 1
        if idle:
            answered = action_deg
            node.send_output("joint_cmd", pa.array(action_deg, type=pa.float64()), {**tag.metadata(), STREAM_KEY: NODE_ID})

    def close() -> None:
        drop()  # an episode cut short by STOP is not a demonstration
        if writer is not None:
            writer.close()
        results.close()

    try:
        if seeds:
            lay_out()
        while index < len(seeds):
            event = node.next(timeout=SILENCE_S)
            if event is None or event["type"] == "STOP":
                return 0
            if event["type"] == "ERROR":  # nothing for SILENCE_S: a message was lost; ask again
                logger.info("[episodes] nothing came for %g s (episode %d, seed %d): asking again", SILENCE_S, index,
                            seeds[index])
                if adopted_index != index:
                    lay_out()  # the reset, or its first frame, went missing
                elif whole:
                    run_again(next_frame)
                else:
                    node.send_output("task_cmd", pa.array([AGAIN_WORD]))
                continue
            if event["type"] != "INPUT":
                continue
            tag = frame_tag(event.get("metadata"))
            if tag is None:
                continue
            if tag.frame == 0 and tag.seed == seeds[index] and tag.episode > adopted:
                begin(tag.episode)  # the body laid it out as asked (the newest such, if asked twice)
            if event["id"] == "action" and tag.episode == adopted:
                metadata = event.get("metadata") or {}
                if metadata.get(NOT_WRITTEN_KEY):
                    not_written.add(tag.frame)
                if isinstance(metadata.get(INFERENCE_MS_KEY), float) and tag.frame not in inferred_ms:
                    inferred_ms[tag.frame] = metadata[INFERENCE_MS_KEY]
            frame = frames.add(event["id"], tag, event["value"])
            if frame is None or tag.episode != adopted or adopted_index != index:
                continue  # not whole yet; or a frame of the body's start, of an episode before, or of one ended
            if tag.frame < next_frame:  # sent again, after a loss
                if idle and answered is not None and tag.frame == next_frame - 1:
                    node.send_output("joint_cmd", pa.array(answered, type=pa.float64()),
                                     {**tag.metadata(), STREAM_KEY: NODE_ID})
                continue
            whole[tag.frame] = (tag, frame)
            while next_frame in whole and adopted_index == index:
                take(*whole.pop(next_frame))
            if adopted_index == index and len(whole) > FrameParts.KEPT:  # next_frame will not come whole now
                run_again(next_frame)
        results.write('"done"\n')
        results.flush()
    except KeyboardInterrupt:
        pass
    except CannotGoOn as error:
        print(f"[{NODE_ID}] cannot go on: {error}", file=sys.stderr, flush=True)
        return 1
    finally:
        close()
    return 0  # the body's task_cmd closes: it ends too


if __name__ == "__main__":
    sys.exit(main())
