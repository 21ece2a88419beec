"""camera: pictures of a simulated arm, drawn in a process of its own.

Each `tick` (the picture rate's timer) draws the latest `joint_state` + `gripper_state` (and, with a
task, its objects where the latest `object_state` puts them) with the one renderer every simulated
body's pictures come from (so101.bodies.task_cameras: MuJoCo's, whichever body simulates) and
publishes it on `image` (uint8 RGB, metadata width, height, encoding "rgb8"), when something moved
since the last one; with a task, the wrist camera's picture too, on `wrist_image`.
A picture of this arm takes a CPU renderer tens of milliseconds (`so101 bench` measures it):
drawn inside the body's physics loop it would hold the loop back, so it is drawn here, below the
body's priority. The recorder takes the latest picture at each of its frames; a policy that sees
(`so101 teleop --policy`), the newest at each of its ticks.
Settings: so101.dataset.settings.CameraSettings.
"""

from __future__ import annotations

import os
import sys
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

# One rendering thread for Mesa's software renderer (MuJoCo's EGL): two cores here, one is the physics'.
os.environ.setdefault("LP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pyarrow as pa  # noqa: E402
from dora import Node  # noqa: E402

from so101.assets import ModelFilesError  # noqa: E402
from so101.bodies.task_cameras import TaskCameras  # noqa: E402
from so101.dataset.features import DEFAULT_FPS  # noqa: E402
from so101.dataset.settings import CameraSettings  # noqa: E402
from so101.runtime.display import DisplayError  # noqa: E402
from so101.robot import HOME_POSE_DEG, NUM_ARM_JOINTS  # noqa: E402
from so101.runtime.dataflow import timer_period_s  # noqa: E402
from so101.runtime.logs import send_diagnostics_to  # noqa: E402
from so101.runtime.node_events import cannot_start, inputs_until_stop  # noqa: E402
from so101.runtime.processes import yield_cpu_to_the_body  # noqa: E402
from so101.tasks import task_named  # noqa: E402

NODE_ID = "camera"
# A pose that moved less than this on every joint since the last picture is not drawn again.
REDRAW_DEG = 0.05
# Nor a task's objects that moved less than this, in metres (or quaternion units).
REDRAW_M = 0.0002


def objects_moved(objects: list[float], drawn: list[float]) -> bool:
    """Whether a task's objects moved by REDRAW_M or more since they were drawn."""
    return len(objects) != len(drawn) or any(abs(now - then) >= REDRAW_M for now, then in zip(objects, drawn))


def stale(stamp: object, period_s: float) -> bool:
    """A tick older than its period waited while a picture was drawn: drawing for it would draw an
    old pose and fall further behind."""
    if not isinstance(stamp, datetime) or stamp.tzinfo is None:
        return False
    return (datetime.now(timezone.utc) - stamp).total_seconds() > period_s


def main() -> int:
    send_diagnostics_to("stdout")
    try:
        settings = CameraSettings.from_environ(os.environ)
        cameras = TaskCameras(task_named(settings.task) if settings.task else None, settings.assets_dir,
                              log=lambda line: None, looks=settings.looks, poses=settings.camera_poses,
                              physics=settings.physics, backdrops=settings.scenario.backdrops)
        width, height = settings.image_size or (0, 0)
        cameras.draw(HOME_POSE_DEG, [], width, height)  # a renderer that cannot work says so now, in one line
    except (ValueError, ModelFilesError, DisplayError, RuntimeError) as error:
        return cannot_start(error, NODE_ID)
    yield_cpu_to_the_body()
    arm_deg: list[float] | None = None
    gripper_deg = 0.0
    drawn_deg: np.ndarray | None = None
    objects_value = None  # the latest object_state (a task's), as it came
    drawn_objects: list[float] = []
    node = Node()
    period_s = timer_period_s(node.node_config()) or 1.0 / DEFAULT_FPS  # a tick that is no timer: the usual rate
    with inputs_until_stop(node, close=cameras.close) as inputs:
        for event in inputs:
            if event["id"] == "joint_state":
                values = event["value"].to_pylist()
                if len(values) == NUM_ARM_JOINTS:
                    arm_deg = values
            elif event["id"] == "gripper_state":
                values = event["value"].to_pylist()
                if len(values) == 1:
                    gripper_deg = values[0]
            elif event["id"] == "object_state":
                objects_value = event["value"]  # read at the next picture, not at each of the 250 a second
            elif event["id"] == "task_status":  # the layout's seed: the pictures' looks and physics, where they vary
                seed = (event["metadata"] or {}).get("seed")
                if isinstance(seed, int) and seed >= 0:
                    before = (cameras.looks, cameras.physics, cameras.placements)
                    cameras.show_seed(seed)
                    if (cameras.looks, cameras.physics, cameras.placements) != before:
                        drawn_deg = None  # drawn again at the next tick, in the new looks
            elif event["id"] == "tick" and arm_deg is not None:
                if stale(event["metadata"].get("timestamp"), period_s):  # waited while drawing: newer states came
                    continue
                objects = objects_value.to_pylist() if objects_value is not None else []
                pose_deg = np.array(arm_deg + [gripper_deg])
                if (drawn_deg is not None and np.all(np.abs(pose_deg - drawn_deg) < REDRAW_DEG)
                        and not objects_moved(objects, drawn_objects)):
                    continue
                rgb, wrist = cameras.draw(pose_deg.tolist(), objects, width, height)
                drawn_deg, drawn_objects = pose_deg, objects
                node.send_output("image", pa.array(rgb.ravel()), {"width": width, "height": height, "encoding": "rgb8"})
                if wrist is not None:
                    node.send_output("wrist_image", pa.array(wrist.ravel()),
                                     {"width": width, "height": height, "encoding": "rgb8"})
    return 0


if __name__ == "__main__":
    sys.exit(main())
