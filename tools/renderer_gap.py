"""How far apart two simulators' pictures of an episode's first frame are: drawn by the one renderer
(so101.bodies.task_cameras) from each body's state, and, for comparison, PyBullet's own TinyRenderer
against that renderer. Mean difference of a channel, of 255, per camera.

    .venv/bin/python tools/renderer_gap.py [--seeds 0 7 12] [--image-size 320x240]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from so101.bodies.camera import DEFAULT_CAMERA, WRIST_CAMERA  # noqa: E402
from so101.bodies.registry import BODIES  # noqa: E402
from so101.bodies.task_cameras import TaskCameras  # noqa: E402
from so101.runtime.argtypes import image_size  # noqa: E402
from so101.tasks import CUBE_TO_BOX  # noqa: E402


def difference(first: np.ndarray, second: np.ndarray) -> float:
    return float(np.mean(np.abs(first.astype(np.int16) - second.astype(np.int16))))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 7, 12])
    parser.add_argument("--image-size", type=image_size, default=(320, 240), metavar="WxH")
    args = parser.parse_args()
    quiet = {"mode": "direct", "log": lambda line: None, "task": CUBE_TO_BOX}
    print("seed | PyBullet vs MuJoCo, one renderer: front, wrist | TinyRenderer vs it: front, wrist | ms: "
          "TinyRenderer front, one renderer both")
    with TaskCameras(CUBE_TO_BOX, log=lambda line: None) as cameras:
        for seed in args.seeds:
            drawn = {}
            for name in ("pybullet", "mujoco"):
                with BODIES[name].body_class()(seed=seed, light_pictures=True, **quiet) as body:
                    body.step()
                    state = (body.joint_angles_deg(), body.scene.object_state())
                    start = time.perf_counter()
                    drawn[name] = cameras.draw(*state, *args.image_size)
                    ours_ms = (time.perf_counter() - start) * 1e3
                    if name == "pybullet":
                        start = time.perf_counter()
                        tiny = (body.render_rgb(*args.image_size, DEFAULT_CAMERA),)
                        tiny_ms = (time.perf_counter() - start) * 1e3
                        tiny += (body.render_rgb(*args.image_size, WRIST_CAMERA),)
            same = [difference(a, b) for a, b in zip(drawn["pybullet"], drawn["mujoco"])]
            apart = [difference(a, b) for a, b in zip(tiny, drawn["pybullet"])]
            print(f"{seed} | {same[0]:.2f}, {same[1]:.2f} | {apart[0]:.1f}, {apart[1]:.1f} | {tiny_ms:.0f}, {ours_ms:.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
