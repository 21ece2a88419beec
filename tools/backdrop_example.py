"""The docs' backdrop pictures (docs/bodies/backdrop.md): a table made here (wood grain under a pale wall, no
photo from elsewhere), and the front camera's picture of seed 3 without and with it, side by side; and the
front picture of seeds 1-4 in varied looks over the backdrop pool (so101.bodies.backdrop_pool).

    python tools/backdrop_example.py OUT_DIR

Writes OUT_DIR/table.png (1280x720), OUT_DIR/backdrop_side_by_side.png (two 320x240 pictures) and
OUT_DIR/backdrop_pool.png (four 240x180 pictures).
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from so101.bodies.task_cameras import TaskCameras  # noqa: E402
from so101.robot import HOME_POSE_DEG  # noqa: E402
from so101.tasks import CUBE_TO_BOX  # noqa: E402


def table(width: int = 1280, height: int = 720) -> np.ndarray:
    """RGB: wood grain (rings bent by two slow waves), a pale wall across the top sixth."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    grain = 0.5 + 0.5 * np.sin(x / 9.0 + 6 * np.sin(y / 140.0) + 2 * np.sin(x / 57.0))
    wood = np.stack([150 + 50 * grain, 100 + 35 * grain, 60 + 20 * grain], axis=-1)
    picture = np.where((y < height / 4.5)[..., None], np.array([205, 210, 215], np.float32), wood)
    return picture.astype(np.uint8)


def main() -> int:
    out = Path(sys.argv[1] if len(sys.argv) > 1 else ".")
    out.mkdir(parents=True, exist_ok=True)
    photo = out / "table.png"
    cv2.imwrite(str(photo), table()[:, :, ::-1])
    pictures = []
    for backdrops in ({}, {"front": str(photo)}):
        with TaskCameras(CUBE_TO_BOX, log=lambda line: None, backdrops=backdrops) as cameras:
            cameras.show_seed(3)
            pictures.append(cameras.draw(HOME_POSE_DEG, [], 320, 240, wrist=False)[0])
    cv2.imwrite(str(out / "backdrop_side_by_side.png"), np.concatenate(pictures, axis=1)[:, :, ::-1])
    pooled = []
    with TaskCameras(CUBE_TO_BOX, log=lambda line: None, looks="varied", backdrops={"front": "pool"}) as cameras:
        for seed in range(1, 5):
            cameras.show_seed(seed)
            pooled.append(cameras.draw(HOME_POSE_DEG, [], 240, 180, wrist=False)[0])
    cv2.imwrite(str(out / "backdrop_pool.png"), np.concatenate(pooled, axis=1)[:, :, ::-1])
    print(f"wrote {photo}, {out / 'backdrop_side_by_side.png'} and {out / 'backdrop_pool.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
