"""recorder: keeps episodes of the arm as a LeRobot dataset (LeRobotDataset v3.0).

`so101 teleop --record DIR` adds this node. Each `tick` (a 5 ms timer) adds the frames due at
the dataset's rate, each with the latest `joint_state` + `gripper_state` (observation.state),
`joint_target` (action: what the body was told) and `image` (the camera node's picture, stored
as video; with a task or a real wrist camera, `wrist_image` too: a real camera's picture is paired with
the state sent nearest its capture), and with a task (SO101_TASK) its `object_state` (observation.environment_state) and
`task_status` (next.success, and next.reward from it); `record_cmd` messages from the prompt start, stop, discard and list episodes, and
each gets its reply on `record_status`, whose metadata also says which episode is recording (the
web view's marker). Saving runs in the background. STOP saves an episode
still recording. What it does is so101/dataset/recording.py; the files, writer.py there.
Settings: so101.dataset.settings.RecorderSettings (SO101_RECORD_DIR, SO101_RECORD_FPS,
SO101_RECORD_IMAGE_SIZE, SO101_LANG).
"""

from __future__ import annotations

import logging
import os
import queue
import sys
import time
from datetime import datetime
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere: the so101 package sits beside nodes/
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
import pyarrow as pa  # noqa: E402
from dora import Node  # noqa: E402

from so101.dataset.features import video_keys_and_sizes  # noqa: E402
from so101.dataset.layout import DatasetError  # noqa: E402
from so101.dataset.messages import decode_record_cmd, recording_metadata  # noqa: E402
from so101.dataset.recording import Recording  # noqa: E402
from so101.dataset.settings import RecorderSettings  # noqa: E402
from so101.dataset.writer import DatasetWriter  # noqa: E402
from so101.runtime.logs import send_diagnostics_to  # noqa: E402
from so101.runtime.node_events import cannot_start  # noqa: E402
from so101.runtime.processes import yield_cpu_to_the_body  # noqa: E402
from so101.tasks import task_named  # noqa: E402

NODE_ID = "recorder"
logger = logging.getLogger("so101.recorder")


def picture(event: dict, image_size: tuple[int, int]) -> np.ndarray | None:
    """The `image` input as (height, width, 3) uint8, or None (logged) for one of another size."""
    width, height = image_size
    pixels = event["value"].to_numpy(zero_copy_only=False)
    if pixels.size != width * height * 3:
        metadata = event.get("metadata") or {}
        logger.warning("[recorder] ignored an image of %sx%s: the dataset's video is %dx%d",
                       metadata.get("width", "?"), metadata.get("height", "?"), width, height)
        return None
    # A copy: the message's memory goes back to dora once the event is dropped, and may carry a later
    # picture by the time this one is written into a frame.
    return np.array(pixels, dtype=np.uint8).reshape(height, width, 3)


def sent_s(event: dict) -> float | None:
    """When a message was sent (dora's stamp, on the wall clock), or None without one."""
    stamp = (event.get("metadata") or {}).get("timestamp")
    return stamp.timestamp() if isinstance(stamp, datetime) and stamp.tzinfo is not None else None


def captured_s(event: dict) -> float | None:
    """When a real camera's picture was taken (its `captured` metadata, wall clock), or None (a simulation's)."""
    captured = (event.get("metadata") or {}).get("captured")
    return float(captured) if isinstance(captured, (int, float)) and not isinstance(captured, bool) else None


def main() -> int:
    send_diagnostics_to("stdout")
    try:
        settings = RecorderSettings.from_environ(os.environ)
        # Opened before joining: a folder that is not this dataset stops the node in one line.
        task = task_named(settings.task) if settings.task else None
        wrist = "wrist" in settings.real_cameras  # the real arm's wrist camera, without a task
        video_sizes = video_keys_and_sizes(settings.image_size, task is not None or wrist, settings.observed)
        writer = DatasetWriter.open(settings.root, settings.fps, video_sizes,
                                    environment_names=task.object_state_names if task else (),
                                    environment_state=settings.observed.environment)
    except (ValueError, DatasetError) as error:
        return cannot_start(error, NODE_ID)
    yield_cpu_to_the_body()
    node = Node()
    if settings.image_size and "image" not in (node.node_config() or {}).get("inputs", {}):
        return cannot_start(ValueError("SO101_RECORD_IMAGE_SIZE is set but no `image` input is connected "
                                       "(empty it to record without video)"), NODE_ID)
    reports: queue.Queue[str] = queue.Queue()  # lines from the save thread, sent from this one
    recording = Recording(writer, str(settings.root), settings.fps, settings.lang,
                          needs_image=settings.image_size is not None, say=reports.put, task=task,
                          scenario=settings.scenario, image_size=settings.image_size,
                          observed=settings.observed, wrist=wrist,
                          camera_lost=settings.camera_lost if settings.real_cameras else "",
                          log=lambda line: logger.info("[recorder] %s", line))

    def send_status(lines: list[str], reply_to: str | None = None) -> None:
        for line in lines:
            logger.info("[recorder] %s", line)
        node.send_output("record_status", pa.array(["\n".join(lines)]),
                         {"reply_to": reply_to or "", **recording_metadata(recording.recording_now())})

    logger.info("[recorder] %s: %d episodes, %d fps, %s", settings.root, len(writer.episodes), settings.fps,
                f"video {settings.image_size[0]}x{settings.image_size[1]}" if settings.image_size else "no video")
    try:
        for event in node:
            if event["type"] == "INPUT":
                name = event["id"]
                if name == "tick":  # on the pictures' clock: a tick read late adds the frames of its time
                    recording.tick(sent_s(event) or time.time())
                elif name == "joint_state":
                    recording.on_joint_state(event["value"].to_pylist(), sent_s(event))
                elif name == "gripper_state":
                    recording.on_gripper_state(event["value"].to_pylist(), sent_s(event))
                elif name == "joint_target":
                    recording.on_joint_target(event["value"].to_pylist())
                elif name == "object_state":
                    recording.on_object_state(event["value"].to_pylist())
                elif name == "task_status":
                    values = event["value"].to_pylist()
                    if len(values) == 1:
                        seed = (event["metadata"] or {}).get("seed")
                        recording.on_task_status(bool(values[0]), seed if isinstance(seed, int) else None)
                elif name == "image" and settings.image_size:
                    rgb = picture(event, settings.image_size)
                    if rgb is not None:
                        recording.on_image(rgb, captured_s(event), sent_s(event))
                elif name == "wrist_image" and settings.image_size:
                    rgb = picture(event, settings.image_size)
                    if rgb is not None:
                        recording.on_wrist_image(rgb, captured_s(event), sent_s(event))
                elif name == "record_cmd":
                    texts = event["value"].to_pylist()
                    reply_to = (event.get("metadata") or {}).get("request", "")
                    send_status(recording.command(decode_record_cmd(str(texts[0]) if texts else "")), reply_to)
                while not reports.empty():
                    send_status([reports.get()])
            elif event["type"] == "STOP":
                break
    except KeyboardInterrupt:
        pass
    finally:
        recording.close()  # an episode still recording is saved, and every save waited for
        while not reports.empty():
            logger.info("[recorder] %s", reports.get())
    return 0


if __name__ == "__main__":
    sys.exit(main())
