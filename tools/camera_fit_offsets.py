"""How well `so101 cameras --fit front` recovers a camera moved away from the simulator's: the figures of
docs/experiments/fitting-cameras.md.

    .venv/bin/python tools/camera_fit_offsets.py [--offsets 6] [--seed 1] [--work /tmp/camera-fits]

For each offset, drawn from --seed: the default front camera's lens moved up to 5 cm, turned up to 10°
(about the vertical, then its own right axis and line of sight) and its field of view changed up to 5°;
one episode of `so101 demos --camera-pose front=FILE --looks varied` (the looks jitter it further);
then the fit from the default camera, against the episode's scenario's `cameras` entry (`so101_episode_scenarios`). One line an
offset (the offset, the fit's error, its residual, its time, and how far the refit draws the episode's
first frame from the frame as drawn and from the video's, mean of 255), then the worst of each.
"""

from __future__ import annotations

import argparse
import json
import math
import random
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from so101.bodies.camera_file import camera_file_from, default_camera_file, orbit_of  # noqa: E402
from so101.dataset.layout import episode_scenario  # noqa: E402
from so101.camera_pose.fit import Pose, _rotation, fit_from_dataset, pose_error  # noqa: E402

# The offsets: the lens up to this far, turned up to this much, the field of view up to this much.
MOVE_M, TURN_DEG, ZOOM_DEG = 0.05, 10.0, 5.0


def offset_camera(draw: random.Random) -> tuple[object, str]:
    """The default front camera moved, turned and zoomed by amounts drawn within the issue's bounds."""
    start = Pose.of(default_camera_file("front"))
    direction = np.array([draw.gauss(0, 1) for _ in range(3)])
    move = direction / np.linalg.norm(direction) * draw.uniform(0.5, 1.0) * MOVE_M
    yaw, pitch, roll = (draw.uniform(-1, 1) for _ in range(3))
    scale = draw.uniform(0.5, 1.0) * TURN_DEG / math.sqrt(yaw ** 2 + pitch ** 2 + roll ** 2)
    axes = _rotation(np.array([0.0, 0.0, math.radians(yaw * scale)])) @ start.axes
    axes = axes @ _rotation(np.array([math.radians(pitch * scale), 0.0, math.radians(roll * scale)]))
    zoom = draw.choice((-1, 1)) * draw.uniform(2.0, ZOOM_DEG)
    moved = Pose(start.eye + move, axes, start.fov_deg + zoom).camera_file(320, 240)
    error_m, error_deg, error_fov = pose_error(moved, default_camera_file("front"))
    return moved, f"moved {100 * error_m:.1f} cm, turned {error_deg:.1f}°, fov {zoom:+.1f}°"


def first_frame_difference(root: Path, fitted: object, truth: object) -> tuple[float, float]:
    """Mean |refit's drawing of the first frame - the first frame as drawn|, and - the video's first frame, of 255."""
    from so101.bodies.task_cameras import TaskCameras
    from so101.dataset.features import ENVIRONMENT_KEY, STATE_KEY, from_lerobot
    from so101.dataset.reader import Dataset
    from so101.tasks import CUBE_TO_BOX

    dataset = Dataset.open(root)
    columns = dataset.episode_frames(0)
    first = next(iter(dataset.episode_images(0, "observation.images.front")))
    seed = int(dataset.info["so101_episode_seeds"]["0"])
    with TaskCameras(CUBE_TO_BOX, log=lambda line: None, looks="varied") as cameras:
        cameras.show_seed(seed)
        drawn, original = (cameras.draw(from_lerobot(columns[STATE_KEY][0]), columns[ENVIRONMENT_KEY][0], 320, 240,
                                        wrist=False, front=orbit_of(camera))[0]  # type: ignore[arg-type]
                           for camera in (fitted, truth))
    return (float(np.abs(drawn.astype(int) - original).mean()), float(np.abs(drawn.astype(int) - first).mean()))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--offsets", type=int, default=6)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--work", type=Path, default=Path("/tmp/camera-fits"))
    args = parser.parse_args()
    draw = random.Random(f"camera offsets {args.seed}")
    args.work.mkdir(parents=True, exist_ok=True)
    worst = [0.0, 0.0, 0.0, 0.0]
    for index in range(args.offsets):
        moved, said = offset_camera(draw)
        pose_file = args.work / f"offset-{index}.json"
        pose_file.write_text(moved.as_json(), encoding="utf-8")  # type: ignore[attr-defined]
        root = args.work / f"episode-{index}"
        if not (root / "meta" / "info.json").is_file():
            subprocess.run([sys.executable, "-m", "so101.cli.main", "demos", str(root), "--task", "cube_to_box",
                            "--episodes", "1", "--seed", str(1000 + index), "--looks", "varied",
                            "--camera-pose", f"front={pose_file}"], check=True, capture_output=True, cwd=ROOT)
        truth = camera_file_from(episode_scenario(json.loads((root / "meta" / "info.json").read_text()), 0)["cameras"]["front"])
        started = time.monotonic()
        try:
            fit = fit_from_dataset(root, default_camera_file("front"))
        except ValueError as error:
            print(f"offset {index} ({said}): no fit: {error}", flush=True)
            worst = [math.inf] * 4
            continue
        took = time.monotonic() - started
        error_m, error_deg, error_fov = pose_error(fit, truth)
        difference, from_video = first_frame_difference(root, fit, truth)
        worst = [max(a, b) for a, b in zip(worst, (1000 * error_m, error_deg, error_fov, difference))]
        print(f"offset {index} ({said}): fit off by {1000 * error_m:.1f} mm, {error_deg:.2f}°, fov {error_fov:.2f}°; "
              f"residual {fit.residual_px:.2f} px; {took:.0f} s; first frame redrawn {difference:.2f} of 255 from the "
              f"frame drawn ({from_video:.2f} from the video's)", flush=True)
    print(f"worst: {worst[0]:.1f} mm, {worst[1]:.2f}°, fov {worst[2]:.2f}°, first frame {worst[3]:.2f} of 255")
    return 0


if __name__ == "__main__":
    sys.exit(main())
