"""web_view: the arm in a browser, for machines with no display (SSH, WSL, a container, a cluster's arm).

Serves a page (so101/web/view.py, with viser) showing the SO-101 from the URDF's meshes, posed
by the body's `joint_state` and `gripper_state`, with the angles as text and a rolling plot; the
camera's `image` where the dataflow has one (`--record` on a simulation), a marker while the
recorder's `record_status` says an episode is recording, and a task's cube and box, posed by the
body's `object_state` (SO101_TASK names the task) and drawn in each layout's look (the seed in the
body's `task_status`, the looks and physics of SO101_SCENARIO). It poses the arm at most REDRAW_HZ
times a second, whatever the body's rate, and runs below the body's priority: a browser
closing, reloading or stalling costs the body nothing. Read-only: the page sends nothing into
the dataflow.
Settings: so101.web.settings.WebViewSettings (SO101_WEB_HOST, SO101_WEB_PORT, SO101_TASK, SO101_SCENARIO).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
from dora import Node  # noqa: E402

from so101.assets import ModelFilesError, urdf_path  # noqa: E402
from so101.bodies.looks import looks_for  # noqa: E402
from so101.bodies.physics import physics_for  # noqa: E402
from so101.bodies.node_loop import announce  # noqa: E402
from so101.dataset.messages import recording_from_metadata  # noqa: E402
from so101.robot import NUM_ARM_JOINTS  # noqa: E402
from so101.runtime.logs import send_diagnostics_to  # noqa: E402
from so101.runtime.node_events import cannot_start, inputs_until_stop  # noqa: E402
from so101.runtime.processes import yield_cpu_to_the_body  # noqa: E402
from so101.tasks import task_named  # noqa: E402
from so101.web.settings import WebViewSettings, page_address  # noqa: E402
from so101.web.urdf_scene import load_urdf_scene  # noqa: E402
from so101.web.view import WebView, layout_look  # noqa: E402

NODE_ID = "web_view"
# A browser's screen refreshes 60 times a second: more poses than that are never seen.
REDRAW_HZ = 60.0
# Camera pictures sent to the page: enough to watch by, each one a JPEG per browser.
PICTURE_HZ = 10.0


def picture(event: dict) -> np.ndarray | None:
    """The camera's `image` as (height, width, 3) uint8, or None if its size is not the metadata's."""
    metadata = event.get("metadata") or {}
    width, height = int(metadata.get("width", 0)), int(metadata.get("height", 0))
    pixels = event["value"].to_numpy(zero_copy_only=False)
    if width * height * 3 != len(pixels) or not width:
        return None
    return np.asarray(pixels, dtype=np.uint8).reshape(height, width, 3)


def main() -> int:
    send_diagnostics_to("stdout")
    try:
        settings = WebViewSettings.from_environ(os.environ)
        scene = load_urdf_scene(urdf_path(settings.assets_dir))
    except (ValueError, ModelFilesError) as error:
        return cannot_start(error, NODE_ID)
    yield_cpu_to_the_body()
    try:
        view = WebView(scene, settings.host, settings.port)
    except OSError as error:  # the port is taken, or the address is not this machine's
        return cannot_start(OSError(f"cannot serve on {settings.host}:{settings.port}: {error.strerror or error}"), NODE_ID)
    task = task_named(settings.task) if settings.task else None
    if task is not None:
        view.add_task(task)
    announce(f"web view: {page_address(settings.host, settings.port)}")
    arm_deg: tuple[float, ...] | None = None
    gripper_deg = 0.0
    shown_at = picture_at = objects_at = 0.0
    with inputs_until_stop(Node(), close=view.close) as inputs:
        for event in inputs:
            if event["id"] == "joint_state":
                values = event["value"].to_pylist()
                if len(values) == NUM_ARM_JOINTS:
                    arm_deg = tuple(float(angle) for angle in values)
            elif event["id"] == "gripper_state":
                values = event["value"].to_pylist()
                if len(values) == 1:
                    gripper_deg = float(values[0])
            elif event["id"] == "image":
                now = time.monotonic()
                if now - picture_at >= 1.0 / PICTURE_HZ and (rgb := picture(event)) is not None:
                    view.show_picture(rgb)
                    picture_at = now
                continue
            elif event["id"] == "object_state":
                now = time.monotonic()
                if now - objects_at >= 1.0 / REDRAW_HZ:
                    view.show_objects(event["value"].to_pylist())
                    objects_at = now
                continue
            elif event["id"] == "task_status":  # the layout's seed: its look, where looks or physics vary
                seed = (event.get("metadata") or {}).get("seed")
                if task is not None and isinstance(seed, int) and seed >= 0:
                    view.show_layout(layout_look(task, looks_for(settings.looks, seed),
                                                 physics_for(settings.physics, seed)))
                continue
            elif event["id"] == "record_status":
                view.show_recording(recording_from_metadata(event.get("metadata") or {}))
                continue
            else:
                continue
            now = time.monotonic()
            if arm_deg is not None and now - shown_at >= 1.0 / REDRAW_HZ:
                view.show(arm_deg + (gripper_deg,))
                shown_at = now
    return 0


if __name__ == "__main__":
    sys.exit(main())
