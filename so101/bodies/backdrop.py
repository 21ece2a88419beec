"""A photo of the user's workspace behind the simulated scene: `--backdrop NAME=IMAGE`.

A real front camera sees a real table, a wall and cables, not the simulator's floor. A backdrop is a
photo (or a folder of photos, one drawn per episode) of the workspace as camera NAME sees it, the arm
out of the way. The renderer (so101.bodies.task_cameras) draws the arm, the cube and the box as
always, and the photo wherever it would have drawn the floor or the empty sky: its segmentation says
which pixels those are. The photo is scaled to cover the picture and cropped at its centre; under
varied looks each episode's seed also shifts and scales it a little (a camera nudged since the photo
was taken still matches) and changes its brightness and tint, as a room's light does. No shading or
shadow is drawn over it: the photo holds the room's own light, and the simulator's shadows are off in
pictures anyway.
"""

from __future__ import annotations

import functools
import hashlib
import random
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from so101.bodies.backdrop_pool import POOL, POOL_HELD_OUT, pool_folder

POOLS = (POOL, POOL_HELD_OUT)
PHOTO_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".webp")
CAMERAS = ("front", "wrist")
SHIFT = 0.03  # of the picture's size, each way, under varied looks
ZOOM = 0.06  # the most the photo is enlarged beyond covering the picture, under varied looks
GAIN = 0.15  # brightness, ± this share, under varied looks
TINT = 0.05  # each colour channel, ± this share, under varied looks


class BackdropError(ValueError):
    """A backdrop that cannot be used; str() is one line."""


def backdrop_photos(path: str | Path) -> tuple[Path, ...]:
    """The photos at `path`: the file, or a folder's images in name order, or a pool's (`pool`,
    `pool-held-out`: so101.bodies.backdrop_pool); BackdropError in one line for a path that is none of
    these, or a folder without images."""
    if str(path) in POOLS:
        return backdrop_photos(pool_folder(str(path)))
    where = Path(path).expanduser()
    if where.is_dir():
        photos = tuple(sorted(item for item in where.iterdir() if item.suffix.lower() in PHOTO_SUFFIXES))
        if not photos:
            raise BackdropError(f"{where} holds no images ({', '.join(PHOTO_SUFFIXES)})")
        return photos
    if not where.is_file():
        raise BackdropError(f"{where} does not exist: give a photo of the workspace, a folder of them, or "
                            f"{' or '.join(POOLS)}")
    return (where,)


@functools.lru_cache(maxsize=16)
def read_photo(path: Path) -> npt.NDArray[np.uint8]:
    """The photo at `path` as RGB, (height, width, 3) uint8; BackdropError in one line where it is not one."""
    import cv2

    picture = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if picture is None:
        raise BackdropError(f"{path} cannot be read as a picture: give a {', '.join(PHOTO_SUFFIXES)} file")
    return np.ascontiguousarray(picture[:, :, ::-1])


@functools.lru_cache(maxsize=16)
def photo_sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def checked_backdrop(text: str) -> tuple[str, str]:
    """NAME=IMAGE as given: the camera's name and the photos' absolute path, each photo read once now;
    BackdropError in one line."""
    name, _, path = text.partition("=")
    if name not in CAMERAS or not path:
        raise BackdropError(f"--backdrop takes NAME=IMAGE, NAME {' or '.join(CAMERAS)}: got {text!r}")
    photos = backdrop_photos(path)
    for photo in photos:
        read_photo(photo.resolve())
    return name, path if path in POOLS else str(Path(path).expanduser().resolve())


@dataclass(frozen=True)
class Placement:
    """One episode's photo and where it sits: `photo` from the folder, shifted by `shift` (of the picture's
    width and height), enlarged `zoom` times past covering it, its colours times `gains` (R, G, B)."""

    photo: Path
    shift: tuple[float, float] = (0.0, 0.0)
    zoom: float = 1.0
    gains: tuple[float, float, float] = (1.0, 1.0, 1.0)

    def as_metadata(self) -> dict[str, object]:
        return {"photo": str(self.photo), "sha256": photo_sha256(self.photo), "shift": list(self.shift),
                "zoom": self.zoom, "gains": list(self.gains)}


def placement_for(path: str, seed: int, varied: bool) -> Placement:
    """Episode seed `seed`'s photo from `path` (a folder: one drawn), and under `varied` looks its shift,
    zoom and colours, drawn apart from the layout's, the looks' and the physics' draws."""
    photos = backdrop_photos(path)
    draw = random.Random(f"so101 backdrop {seed}")
    photo = photos[draw.randrange(len(photos))].resolve()
    if not varied:
        return Placement(photo)
    shift = (round(draw.uniform(-SHIFT, SHIFT), 4), round(draw.uniform(-SHIFT, SHIFT), 4))
    gain = draw.uniform(1 - GAIN, 1 + GAIN)
    gains = tuple(round(gain * draw.uniform(1 - TINT, 1 + TINT), 4) for _ in range(3))
    return Placement(photo, shift, round(1 + draw.uniform(0, ZOOM), 4), gains)  # type: ignore[arg-type]


def fitted(photo: npt.NDArray[np.uint8], width: int, height: int, shift: tuple[float, float] = (0.0, 0.0),
           zoom: float = 1.0) -> npt.NDArray[np.uint8]:
    """`photo` scaled to cover a width x height picture (times `zoom`) and cropped about its centre moved by
    `shift` (of the picture's size): any size and aspect fits."""
    import cv2

    rows, columns = photo.shape[:2]
    scale = max(width / columns, height / rows) * zoom
    scaled_w, scaled_h = max(width, round(columns * scale)), max(height, round(rows * scale))
    scaled = cv2.resize(photo, (scaled_w, scaled_h), interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
    left = min(max(0, (scaled_w - width) // 2 + round(shift[0] * width)), scaled_w - width)
    top = min(max(0, (scaled_h - height) // 2 + round(shift[1] * height)), scaled_h - height)
    return np.ascontiguousarray(scaled[top:top + height, left:left + width])


@functools.lru_cache(maxsize=32)
def backdrop_picture(placement: Placement, width: int, height: int) -> npt.NDArray[np.uint8]:
    """What `placement` shows behind a width x height picture."""
    picture = fitted(read_photo(placement.photo), width, height, placement.shift, placement.zoom).astype(np.float32)
    return np.clip(picture * np.asarray(placement.gains, dtype=np.float32), 0, 255).astype(np.uint8)
