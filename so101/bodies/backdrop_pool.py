"""Backdrops for eyes that never saw the user's table: `--backdrop front=pool` and the default recipe.

Eyes taught over one floor colour learn that floor. A pool of workspaces, drawn behind the scene for
some of the eyes' pictures, makes a table they never saw less of a new world (Tobin et al. 2017).
Nothing is downloaded and nothing is copied into this repository; the pool is made on first use in the
user's cache, the same on every machine, from two sources:
- **photographs**: the ten panoramas viser ships for its 3D view (`viser/_assets/hdri`, from Poly
  Haven, CC0), each seen through a perspective camera looking down at its floor from several headings
  and pitches: concrete, wood floors, a studio's floor with cables, pavement, grass, rock;
- **surfaces made here**: wood grain, desk mats, cutting mats, concrete, laminate (and, held out,
  fabric and tiles), seen in perspective, some with a wall, cables or paper on them, under uneven light.

Two parts never meet: `pool` is the default recipe's; `pool-held-out` (two panoramas and two surfaces
of its own) is what `--looks unseen` draws behind the front camera, to score eyes on workspaces they
never saw. Either name is accepted wherever a backdrop's path is (so101.bodies.backdrop).
"""

from __future__ import annotations

import importlib.util
import math
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

POOL = "pool"
POOL_HELD_OUT = "pool-held-out"
POOL_VERSION = 1  # a change to what the pool holds makes a new folder: datasets name their photos by path and sha256
SIZE = (320, 240)  # width, height: twice the eyes' pictures
HELD_OUT_PANORAMAS = ("st_fagans_interior", "potsdamer_platz")
SURFACES = ("wood", "desk_mat", "cutting_mat", "concrete", "laminate", "fabric", "tiles")
HELD_OUT_SURFACES = ("fabric", "tiles")
VIEWS_PER_PANORAMA = 10
PER_SURFACE = 16
SOURCES_FILE = "SOURCES.txt"

Rgb = npt.NDArray[np.uint8]


def with_unseen_pool(looks: str, backdrops: dict[str, str]) -> dict[str, str]:
    """`backdrops` as drawn in `looks`: unseen looks draw the front camera's from the held-out pool where
    none is given."""
    if looks == "unseen" and "front" not in backdrops:
        return {**backdrops, "front": POOL_HELD_OUT}
    return dict(backdrops)


def pool_folder(name: str) -> Path:
    """The folder of pool `name` (POOL or POOL_HELD_OUT), made on first use in the user's cache."""
    if name not in (POOL, POOL_HELD_OUT):
        raise ValueError(f"the backdrop pools are {POOL} and {POOL_HELD_OUT}, not {name!r}")
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    folder = cache / "so101" / "backdrops" / f"v{POOL_VERSION}" / name
    if not (folder / SOURCES_FILE).is_file():
        _make(folder, held_out=name == POOL_HELD_OUT)
    return folder


def panoramas() -> tuple[Path, ...]:
    """The panoramas viser ships (none where viser is not installed)."""
    spec = importlib.util.find_spec("viser")
    if spec is None or not spec.submodule_search_locations:
        return ()
    folder = Path(list(spec.submodule_search_locations)[0]) / "_assets" / "hdri"
    return tuple(sorted(folder.glob("*_1k.jpg")))


def _make(folder: Path, held_out: bool) -> None:
    """Writes the pool's pictures and SOURCES.txt whole (into a folder beside it, then renamed): two
    processes making it at once each make a whole one, and the second's rename finds the first's."""
    folder.parent.mkdir(parents=True, exist_ok=True)
    making = Path(tempfile.mkdtemp(prefix=f".{folder.name}-", dir=folder.parent))
    try:
        _write(making, held_out)
        making.rename(folder)
    except OSError:
        if not (folder / SOURCES_FILE).is_file():  # not another process that made it first
            raise
    finally:
        shutil.rmtree(making, ignore_errors=True)


def _write(making: Path, held_out: bool) -> None:
    import cv2

    sources = []
    for panorama in panoramas():
        name = panorama.name.removesuffix("_1k.jpg")
        if (name in HELD_OUT_PANORAMAS) != held_out:
            continue
        picture: Rgb = np.asarray(cv2.imread(str(panorama), cv2.IMREAD_COLOR), dtype=np.uint8)[:, :, ::-1]
        draw = np.random.default_rng(list(name.encode()))
        for view in range(VIEWS_PER_PANORAMA):
            heading, pitch, fov = draw.uniform(0, 360), draw.uniform(30, 60), draw.uniform(50, 70)
            file = f"photo-{name}-{view:02d}.png"
            cv2.imwrite(str(making / file), np.ascontiguousarray(view_of_panorama(picture, heading, pitch, fov)[:, :, ::-1]))
            sources.append(f"{file}: Poly Haven's {name} panorama (CC0), as viser ships it, looking {pitch:.0f}° down "
                           f"at heading {heading:.0f}°, field of view {fov:.0f}°")
    for surface in SURFACES:
        if (surface in HELD_OUT_SURFACES) != held_out:
            continue
        for index in range(PER_SURFACE):
            file = f"made-{surface}-{index:02d}.png"
            picture = made_workspace(surface, np.random.default_rng([SURFACES.index(surface), index]))
            cv2.imwrite(str(making / file), np.ascontiguousarray(picture[:, :, ::-1]))
            sources.append(f"{file}: {surface.replace('_', ' ')} made by so101.bodies.backdrop_pool (this project)")
    (making / SOURCES_FILE).write_text("\n".join(sources) + "\n", encoding="utf-8")


def view_of_panorama(panorama: Rgb, heading_deg: float, pitch_deg: float, fov_deg: float,
                     size: tuple[int, int] = SIZE) -> Rgb:
    """What a camera at the panorama's centre sees, looking `pitch_deg` below the horizon towards
    `heading_deg`, with a horizontal field of view `fov_deg`, at `size` (width, height). The panorama is
    equirectangular: longitude across, latitude down."""
    import cv2

    width, height = size
    rows, columns = panorama.shape[:2]
    heading, pitch = math.radians(heading_deg), math.radians(pitch_deg)
    focal = (width / 2) / math.tan(math.radians(fov_deg) / 2)
    forward = np.array([math.cos(pitch) * math.cos(heading), math.cos(pitch) * math.sin(heading), -math.sin(pitch)])
    right = np.array([math.sin(heading), -math.cos(heading), 0.0])
    up = np.cross(right, forward)
    u, v = np.meshgrid(np.arange(width) + 0.5 - width / 2, np.arange(height) + 0.5 - height / 2)
    rays = forward + (u / focal)[..., None] * right - (v / focal)[..., None] * up
    longitude = np.arctan2(rays[..., 1], rays[..., 0])
    latitude = np.arctan2(rays[..., 2], np.hypot(rays[..., 0], rays[..., 1]))
    map_x = ((longitude / (2 * math.pi) + 0.5) * columns).astype(np.float32)
    map_y = ((0.5 - latitude / math.pi) * rows).astype(np.float32)
    seen = cv2.remap(np.ascontiguousarray(panorama), map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
    return np.asarray(seen, dtype=np.uint8)


def _pick(draw: np.random.Generator, options: list[tuple[float, float, float]]) -> tuple[float, float, float]:
    return tuple(float(value) for value in options[int(draw.integers(len(options)))])  # type: ignore[return-value]


def _smooth_noise(draw: np.random.Generator, shape: tuple[int, int], cells: int) -> npt.NDArray[np.float32]:
    """Noise in [-1, 1] that varies over about `cells` cells across the shorter side."""
    import cv2

    rows, columns = shape
    small = draw.uniform(-1, 1, (max(2, cells * rows // min(shape)), max(2, cells * columns // min(shape))))
    noise = cv2.resize(small.astype(np.float32), (columns, rows), interpolation=cv2.INTER_CUBIC)
    return np.asarray(noise, dtype=np.float32)


def _surface(kind: str, draw: np.random.Generator, shape: tuple[int, int]) -> npt.NDArray[Any]:
    """A flat surface of `kind`, RGB floats 0-255, seen straight down."""
    rows, columns = shape
    y, x = np.mgrid[0:rows, 0:columns].astype(np.float32)
    base = np.ones((rows, columns, 1), np.float32)
    if kind == "wood":
        rgb = np.asarray(_pick(draw, [(190, 150, 105), (150, 100, 60), (215, 185, 140), (110, 70, 45), (175, 120, 70)]), np.float32)
        angle = draw.uniform(0, math.pi)
        along = x * math.cos(angle) + y * math.sin(angle)
        across = -x * math.sin(angle) + y * math.cos(angle)
        grain = np.sin(across / draw.uniform(4, 12) + draw.uniform(3, 9) * np.sin(along / draw.uniform(80, 200))
                       + 4 * _smooth_noise(draw, shape, 4))
        planks = (np.floor(across / draw.uniform(90, 220)) % 2)[..., None] * draw.uniform(-18, 18)
        wood: npt.NDArray[Any] = base * rgb * (1 + 0.12 * grain[..., None]) + planks
        return wood
    if kind == "desk_mat":
        rgb = np.asarray(_pick(draw, [(40, 40, 44), (70, 75, 85), (30, 60, 110), (40, 90, 60), (120, 120, 125), (150, 110, 80)]), np.float32)
        return base * rgb * (1 + 0.05 * _smooth_noise(draw, shape, 12)[..., None])
    if kind == "cutting_mat":
        rgb = np.asarray(_pick(draw, [(40, 110, 80), (40, 80, 130), (60, 60, 65)]), np.float32)
        pitch = draw.uniform(18, 40)
        lines = (np.minimum(x % pitch, y % pitch) < 1.5)[..., None]
        return np.where(lines, rgb + 90, base * rgb)
    if kind == "concrete":
        grey = draw.uniform(110, 190)
        noise = 0.6 * _smooth_noise(draw, shape, 6) + 0.3 * _smooth_noise(draw, shape, 40) + 0.2 * draw.uniform(-1, 1, shape)
        return base * (grey + 25 * noise[..., None]) * np.asarray(draw.uniform(0.95, 1.05, 3), np.float32)
    if kind == "laminate":
        rgb = np.asarray(_pick(draw, [(235, 235, 232), (225, 220, 210), (205, 208, 212), (240, 238, 225)]), np.float32)
        return base * rgb * (1 + 0.03 * _smooth_noise(draw, shape, 5)[..., None])
    if kind == "fabric":
        rgb = np.asarray(_pick(draw, [(120, 40, 50), (60, 70, 110), (150, 140, 110), (70, 100, 90)]), np.float32)
        period = draw.uniform(3, 6)
        weave = np.sin(x / period) * np.sin(y / period)
        fabric: npt.NDArray[Any] = base * rgb * (1 + 0.15 * weave[..., None] + 0.05 * _smooth_noise(draw, shape, 8)[..., None])
        return fabric
    if kind == "tiles":
        rgb = np.asarray(_pick(draw, [(200, 195, 185), (150, 170, 180), (180, 120, 90), (90, 90, 95)]), np.float32)
        side = draw.uniform(50, 120)
        grout = (np.minimum(x % side, y % side) < 3)[..., None]
        return np.where(grout, np.float32(225), base * rgb * (1 + 0.04 * _smooth_noise(draw, shape, 20)[..., None]))
    raise ValueError(f"no surface {kind!r}: {', '.join(SURFACES)}")


def made_workspace(kind: str, draw: np.random.Generator, size: tuple[int, int] = SIZE) -> Rgb:
    """A workspace of surface `kind` as a camera looking down at it sees one: in perspective, perhaps a
    wall across the top, cables or a sheet of paper on it, under light that falls off across it."""
    import cv2

    width, height = size
    flat = _surface(kind, draw, (2 * height, 2 * width))
    for _ in range(int(draw.integers(0, 3))):  # sheets of paper, sticky notes
        centre = (float(draw.uniform(0, 2 * width)), float(draw.uniform(0, 2 * height)))
        sides = (float(draw.uniform(30, 160)), float(draw.uniform(30, 200)))
        corners = cv2.boxPoints((centre, sides, float(draw.uniform(0, 90)))).astype(np.int32)
        cv2.fillConvexPoly(flat, corners, _pick(draw, [(245, 245, 240), (250, 235, 120), (230, 230, 235)]))
    for _ in range(int(draw.integers(0, 3))):  # cables
        start, bend, end = (draw.uniform(0, 1, 2) * (2 * width, 2 * height) for _ in range(3))
        t = np.linspace(0, 1, 60)[:, None]
        curve = ((1 - t) ** 2 * start + 2 * (1 - t) * t * bend + t ** 2 * end).astype(np.int32)
        shade = float(draw.uniform(10, 60)) if draw.random() < 0.8 else 230.0
        cv2.polylines(flat, [curve], False, (shade, shade, shade), int(draw.integers(4, 10)), cv2.LINE_AA)
    # Perspective: the far edge narrower, as a camera looking down at a slant sees a table.
    narrow = draw.uniform(0.15, 0.35) * 2 * width
    source = np.array([[narrow, 0], [2 * width - narrow, 0], [2 * width, 2 * height], [0, 2 * height]], np.float32)
    target = np.array([[0, 0], [width, 0], [width, height], [0, height]], np.float32)
    picture = cv2.warpPerspective(flat, cv2.getPerspectiveTransform(source, target), (width, height),
                                  flags=cv2.INTER_AREA, borderMode=cv2.BORDER_REFLECT)
    if draw.random() < 0.5:  # a wall behind the table
        top = int(draw.uniform(0.08, 0.3) * height)
        wall = np.asarray(_pick(draw, [(225, 225, 220), (200, 205, 215), (235, 225, 205), (160, 170, 165)]), np.float32)
        fall = np.linspace(1.05, 0.9, top, dtype=np.float32)[:, None, None]
        picture[:top] = wall * fall
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    angle = draw.uniform(0, 2 * math.pi)
    light = 1 + draw.uniform(0.05, 0.25) * ((x / width - 0.5) * math.cos(angle) + (y / height - 0.5) * math.sin(angle))
    workspace: Rgb = np.clip(picture * light[..., None], 0, 255).astype(np.uint8)
    return workspace
