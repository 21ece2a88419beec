"""real_camera: the pictures of one real camera (a USB camera through OpenCV's V4L2, or a video file
standing in for one), with the simulated camera node's output: `image`, uint8 RGB, metadata width,
height, encoding; and in its metadata too `captured`, when the picture was taken (wall clock,
seconds; the camera driver's time where it gives one), so the recorder pairs it with the arm's
state of that moment, and `frame`, its number.
One node per camera (`so101 teleop --camera front=... --camera wrist=...`).

The capture runs in a thread at the camera's own pace (so101.cameras.capture); each `tick` (a 5 ms
timer) sends the newest picture once. A camera that stops is said in one line and tried again every
second; the node goes on, and says when it is back. Its settings keep dora-hub's
`opencv-video-capture` contract (CAPTURE_PATH, IMAGE_WIDTH, IMAGE_HEIGHT, ENCODING).
Settings: so101.cameras.settings.RealCameraSettings.
"""

from __future__ import annotations

import logging
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
import pyarrow as pa  # noqa: E402
from dora import Node  # noqa: E402

from so101.cameras.capture import Capturing, VideoSource  # noqa: E402
from so101.cameras.settings import RealCameraSettings  # noqa: E402
from so101.runtime.logs import send_diagnostics_to  # noqa: E402
from so101.runtime.node_events import cannot_start, inputs_until_stop  # noqa: E402

logger = logging.getLogger("so101.real_camera")


def main() -> int:
    send_diagnostics_to("stdout")
    try:
        settings = RealCameraSettings.from_environ(os.environ)
    except ValueError as error:
        return cannot_start(error, "camera")
    node_id = f"camera_{settings.name}"
    source = VideoSource(settings.source, settings.size, settings.capture_size or settings.size, settings.fps)
    capturing = Capturing(source, settings.name, str(settings.source), lambda line: logger.warning("[%s] %s", node_id, line))
    capturing.start()
    node = Node()
    sent = -1
    with inputs_until_stop(node, close=capturing.stop) as inputs:
        for event in inputs:
            if event["id"] != "tick":
                continue
            if capturing.failed:
                return 1
            picture = capturing.latest
            if picture is None or picture.number == sent:
                continue
            sent = picture.number
            pixels = picture.rgb if settings.encoding == "rgb8" else picture.rgb[:, :, ::-1]
            height, width = pixels.shape[:2]
            node.send_output("image", pa.array(np.ascontiguousarray(pixels).ravel()),
                             {"width": width, "height": height, "encoding": settings.encoding,
                              "captured": picture.captured_s, "frame": picture.number})
    return 0


if __name__ == "__main__":
    sys.exit(main())
