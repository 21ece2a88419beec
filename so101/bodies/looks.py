"""How a task's pictures look, drawn from the episode's seed: `--looks varied`.

A policy that sees, trained on one floor colour, one light and one camera placement, learns those
too. With varied looks each episode's seed draws its own: the light's direction and strength, the
colours of the floor and of the task's objects (the cube, the box) from small palettes, the front
camera's place (±1 cm), aim (±2°) and field of view (±2°), and the wrist camera's place within its
mount's tolerance (±2 mm) and its field of view (±2°). The same seed gives the same looks on every
machine and on both simulators (Python's `random.Random`, seeded by text, is the same on every
platform); `fixed` (the default) keeps the pictures as they always were. `unseen` draws looks held out
of `varied`, to score how eyes taught on `varied` do on looks they never saw, as a real camera's will
be: colours from palettes of their own, a lower, dimmer or brighter light, and the cameras moved and
turned beyond `varied`'s spread (front 1-2 cm, 2-3°; field of view 2-3°; wrist 2-3 mm), and (drawn by the
renderer) the front camera's backdrop from the pool held out of the eyes' pictures (so101.bodies.backdrop_pool). Pure: the renderer
(so101.bodies.task_cameras) applies them; a dataset keeps them by episode (`as_metadata`).
"""

from __future__ import annotations

import json
import math
import random
from dataclasses import asdict, dataclass

LOOKS_CHOICES = ("fixed", "varied", "unseen")
DEFAULT_LOOKS = "fixed"

Rgba = tuple[float, float, float, float]

# Floors a desk or a lab might have: light grey (the fixed look's), white, warm wood, dark grey, green mat, beige.
FLOOR_PALETTE: tuple[Rgba, ...] = (
    (0.85, 0.87, 0.92, 1.0), (0.95, 0.95, 0.95, 1.0), (0.62, 0.45, 0.30, 1.0), (0.35, 0.36, 0.38, 1.0),
    (0.30, 0.50, 0.35, 1.0), (0.82, 0.76, 0.62, 1.0),
)
# The objects' colours, each object a different one: red, blue, green, yellow, orange, purple, white, black.
OBJECT_PALETTE: tuple[Rgba, ...] = (
    (0.85, 0.25, 0.20, 1.0), (0.25, 0.45, 0.80, 1.0), (0.25, 0.65, 0.30, 1.0), (0.90, 0.80, 0.20, 1.0),
    (0.95, 0.55, 0.15, 1.0), (0.55, 0.30, 0.70, 1.0), (0.92, 0.92, 0.90, 1.0), (0.12, 0.12, 0.14, 1.0),
)
# `unseen`'s palettes: none of these is in the two above.
UNSEEN_FLOOR_PALETTE: tuple[Rgba, ...] = (
    (0.55, 0.75, 0.85, 1.0), (0.90, 0.72, 0.76, 1.0), (0.32, 0.24, 0.18, 1.0), (0.70, 0.70, 0.55, 1.0),
)
UNSEEN_OBJECT_PALETTE: tuple[Rgba, ...] = (
    (0.20, 0.80, 0.85, 1.0), (0.90, 0.40, 0.70, 1.0), (0.55, 0.35, 0.20, 1.0), (0.10, 0.45, 0.45, 1.0),
    (0.60, 0.90, 0.20, 1.0), (0.50, 0.50, 0.52, 1.0),
)
FRONT_SHIFT_M = 0.01
FRONT_TURN_DEG = 2.0
FOV_DEG = 2.0
WRIST_SHIFT_M = 0.002
# The light comes from above, from any side: elevation 40-80° above the floor; strength as MuJoCo's diffuse.
LIGHT_ELEVATION_DEG = (40.0, 80.0)
LIGHT_DIFFUSE = (0.45, 0.95)
# `unseen`'s: how far beyond `varied`'s spread each goes (x its spread), and its light.
UNSEEN_BEYOND = 1.5
UNSEEN_LIGHT_ELEVATION_DEG = (25.0, 40.0)
UNSEEN_LIGHT_DIFFUSE = ((0.3, 0.45), (0.95, 1.1))


@dataclass(frozen=True)
class Looks:
    """One episode's looks: what the renderer changes from the fixed ones."""

    seed: int
    light_dir: tuple[float, float, float]  # a unit vector, where the light shines to
    light_diffuse: float
    floor_rgba: Rgba
    object_rgbas: tuple[Rgba, ...]  # the task's objects in the model's order (cube_to_box: the cube, the box)
    front_shift_m: tuple[float, float, float]  # added to the front camera's target
    front_turn_deg: tuple[float, float]  # added to its yaw and pitch
    front_fov_deg: float  # added to its field of view
    wrist_shift_m: tuple[float, float, float]  # added to the wrist camera's place, in the gripper's frame
    wrist_fov_deg: float  # added to its field of view

    def as_metadata(self) -> dict[str, object]:
        """The looks as a dataset keeps them (JSON), by episode."""
        metadata: dict[str, object] = json.loads(json.dumps(asdict(self)))
        return metadata


def _around(draw: random.Random, spread: float) -> float:
    return round(draw.uniform(-spread, spread), 6)


def _around3(draw: random.Random, spread: float) -> tuple[float, float, float]:
    return (_around(draw, spread), _around(draw, spread), _around(draw, spread))


def varied_looks(seed: int, objects: int = 2) -> Looks:
    """The looks of episode seed `seed` (a whole number >= 0), for a task with `objects` objects."""
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"a seed is a whole number >= 0, got {seed!r}")
    if not 0 <= objects <= len(OBJECT_PALETTE):
        raise ValueError(f"looks colour at most {len(OBJECT_PALETTE)} objects, not {objects}")
    draw = random.Random(f"so101 looks {seed}")  # apart from the layout's draws: the same seed, another sequence
    azimuth = math.radians(draw.uniform(0.0, 360.0))
    elevation = math.radians(draw.uniform(*LIGHT_ELEVATION_DEG))
    light_dir = (round(-math.cos(elevation) * math.cos(azimuth), 6), round(-math.cos(elevation) * math.sin(azimuth), 6),
                 round(-math.sin(elevation), 6))
    return Looks(
        seed=seed, light_dir=light_dir, light_diffuse=round(draw.uniform(*LIGHT_DIFFUSE), 6),
        floor_rgba=draw.choice(FLOOR_PALETTE), object_rgbas=tuple(draw.sample(OBJECT_PALETTE, objects)),
        front_shift_m=_around3(draw, FRONT_SHIFT_M),
        front_turn_deg=(_around(draw, FRONT_TURN_DEG), _around(draw, FRONT_TURN_DEG)),
        front_fov_deg=_around(draw, FOV_DEG), wrist_shift_m=_around3(draw, WRIST_SHIFT_M),
        wrist_fov_deg=_around(draw, FOV_DEG),
    )


def _beyond(draw: random.Random, spread: float) -> float:
    """A value past ±spread, up to ±UNSEEN_BEYOND x spread, either side."""
    return round(draw.choice((-1.0, 1.0)) * draw.uniform(spread, UNSEEN_BEYOND * spread), 6)


def unseen_looks(seed: int, objects: int = 2) -> Looks:
    """The held-out looks of episode seed `seed`: what `varied` never draws (the module's doc)."""
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"a seed is a whole number >= 0, got {seed!r}")
    if not 0 <= objects <= len(UNSEEN_OBJECT_PALETTE):
        raise ValueError(f"unseen looks colour at most {len(UNSEEN_OBJECT_PALETTE)} objects, not {objects}")
    draw = random.Random(f"so101 unseen looks {seed}")
    azimuth = math.radians(draw.uniform(0.0, 360.0))
    elevation = math.radians(draw.uniform(*UNSEEN_LIGHT_ELEVATION_DEG))
    light_dir = (round(-math.cos(elevation) * math.cos(azimuth), 6), round(-math.cos(elevation) * math.sin(azimuth), 6),
                 round(-math.sin(elevation), 6))
    return Looks(
        seed=seed, light_dir=light_dir, light_diffuse=round(draw.uniform(*draw.choice(UNSEEN_LIGHT_DIFFUSE)), 6),
        floor_rgba=draw.choice(UNSEEN_FLOOR_PALETTE), object_rgbas=tuple(draw.sample(UNSEEN_OBJECT_PALETTE, objects)),
        front_shift_m=(_beyond(draw, FRONT_SHIFT_M), _beyond(draw, FRONT_SHIFT_M), _beyond(draw, FRONT_SHIFT_M)),
        front_turn_deg=(_beyond(draw, FRONT_TURN_DEG), _beyond(draw, FRONT_TURN_DEG)),
        front_fov_deg=_beyond(draw, FOV_DEG),
        wrist_shift_m=(_beyond(draw, WRIST_SHIFT_M), _beyond(draw, WRIST_SHIFT_M), _beyond(draw, WRIST_SHIFT_M)),
        wrist_fov_deg=_beyond(draw, FOV_DEG),
    )


def looks_for(mode: str, seed: int, objects: int = 2) -> Looks | None:
    """`mode`'s looks for episode seed `seed`: None for fixed (the pictures as they always were)."""
    if mode not in LOOKS_CHOICES:
        raise ValueError(f"unknown looks {mode!r}; use one of: {', '.join(LOOKS_CHOICES)}")
    if mode == "fixed":
        return None
    return varied_looks(seed, objects) if mode == "varied" else unseen_looks(seed, objects)


def looks_metadata(mode: str, seed: int, objects: int = 2) -> dict[str, object]:
    """What a dataset keeps of an episode's looks: {"looks": "fixed"}, or the varied ones drawn."""
    looks = looks_for(mode, seed, objects)
    return {"looks": mode} if looks is None else {"looks": mode, **looks.as_metadata()}
