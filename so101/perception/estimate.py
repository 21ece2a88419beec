"""From the eyes' maps to the task's object_state: where the cube is in the picture, then, through the
camera's geometry, in the world. Pure numpy: the perception node, the training's check and the tests
share it.

The cube's pixel and its height above the floor (the maps say both) give its centre: the point on the
pixel's ray at that height. The front camera's place is known only roughly (a person places a real
one by tape measure; `--looks varied` moves the simulated one by up to 1 cm and 2°, which moves a
point on the table by up to 2 cm), so the cube is placed against landmarks whose places are known
and which the eyes also find: the box, which stands where the task puts it, and the gripper's tip,
where the joints put it (forward kinematics: a real arm knows its joints). Each landmark's error,
seen against known, is the camera's error near it; the cube takes the landmarks' errors weighted by
how near each is to it in the picture, so as the jaws close on the cube, the tip, beside it, cancels
almost all of the camera's error. The box's own state is the task's fact, not a measurement.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import numpy.typing as npt

from so101.perception.geometry import View
from so101.tasks.objects import Box, Cube

STRIDE = 4  # picture pixels per cell of the maps 
KEYPOINTS = ("cube", "box", "tip")  # the heat maps' order
LIFT_SCALE_M = 0.1  # the lift channel: the cube centre's height above lying on the floor, in these
BOX_POINT_HEIGHT_M = Box().floor_thickness_m  # the box's point the eyes find: its floor's top face's centre
# A landmark this many pixels from the cube counts half as much as one on it.
LANDMARK_REACH_PX = 12.0
# A landmark whose map puts less than this share at its peak is not trusted (hidden, or out of the picture).
LANDMARK_SURE = 0.3


@dataclass(frozen=True)
class Sighting:
    """What one picture's maps say: each keypoint's pixel (u, v) and how sure its map is (its peak's
    share, 0-1), the cube's yaw (folded into ±45°) and its height above lying on the floor."""

    pixels: dict[str, tuple[float, float]]
    sure: dict[str, float]
    cube_yaw_rad: float
    cube_lift_m: float


def _peak(logits: npt.NDArray[np.floating]) -> tuple[int, int, float]:
    flat = logits.reshape(-1).astype(np.float64)
    weights = np.exp(flat - flat.max())
    weights /= weights.sum()
    row, column = divmod(int(np.argmax(flat)), logits.shape[1])
    grid = weights.reshape(logits.shape)  # the peak's share: its 3x3 neighbourhood's weight
    return row, column, float(grid[max(row - 1, 0):row + 2, max(column - 1, 0):column + 2].sum())


def read_maps(maps: npt.NDArray[np.floating]) -> Sighting:
    """One picture's maps (so101.perception.net.CHANNELS, in cells) -> its Sighting, in pixels."""
    pixels, sure, cells = {}, {}, {}
    for index, name in enumerate(KEYPOINTS):
        row, column, share = _peak(maps[index])
        du, dv = (float(maps[len(KEYPOINTS) + 2 * index + axis, row, column]) for axis in (0, 1))
        pixels[name] = ((column + 0.5 + du) * STRIDE, (row + 0.5 + dv) * STRIDE)
        sure[name], cells[name] = share, (row, column)
    row, column = cells["cube"]
    first = 3 * len(KEYPOINTS)
    yaw = math.atan2(float(maps[first + 1, row, column]), float(maps[first, row, column])) / 4
    lift = max(0.0, float(maps[first + 2, row, column]) * LIFT_SCALE_M)
    return Sighting(pixels, sure, yaw, lift)


def cube_in_world(sighting: Sighting, view: View, cube: Cube, box: Box, tip_m: Sequence[float] | None = None,
                  landmarks: bool = True) -> npt.NDArray[np.float64]:
    """The cube's centre (x, y, z) in the base frame, seen through `view` (the camera as it is believed
    to be); with `landmarks`, corrected by the box and, given `tip_m` (the tip where the joints put
    it), by the tip (see the module's doc)."""
    centre: npt.NDArray[np.float64] = view.on_plane([sighting.pixels["cube"]], cube.half_size_m + sighting.cube_lift_m)[0]
    if not landmarks:
        return centre
    known: dict[str, tuple[float, ...]] = {"box": (*box.xy_m, BOX_POINT_HEIGHT_M)}
    if tip_m is not None:
        known["tip"] = tuple(float(value) for value in tip_m)
    cube_px = np.asarray(sighting.pixels["cube"])
    errors, weights = [], []
    for name, where in known.items():
        if sighting.sure[name] < LANDMARK_SURE:
            continue
        seen = view.on_plane([sighting.pixels[name]], where[2])[0]
        if not np.all(np.isfinite(seen)):
            continue
        errors.append(np.asarray(where[:2]) - seen[:2])
        distance = float(np.hypot(*(np.asarray(sighting.pixels[name]) - cube_px)))
        weights.append(1.0 / (1.0 + (distance / LANDMARK_REACH_PX) ** 2))
    if weights:
        centre[:2] += np.average(np.asarray(errors), axis=0, weights=weights)
    return centre


def object_state(sighting: Sighting, view: View, cube: Cube, box: Box, tip_m: Sequence[float] | None = None,
                 landmarks: bool = True) -> list[float]:
    """The task's object_state (so101.tasks.objects.OBJECT_STATE_NAMES) as the eyes see it: the cube's
    centre and a level quaternion at its yaw; the box where the task stands it."""
    x, y, z = cube_in_world(sighting, view, cube, box, tip_m, landmarks)
    half = sighting.cube_yaw_rad / 2
    return [float(x), float(y), float(z), 0.0, 0.0, math.sin(half), math.cos(half), *box.xy_m, 0.0]


# Below this share at its peak, the cube's map is not trusted (the arm hides it, or it left the picture).
CUBE_SURE = 0.2
# The newest this many sure sightings make the cube's place (their median: one picture's outlier is
# out-voted), unless the newest is farther than FILTER_JUMP_M from it: then the cube moved (the jaws
# lifted it), and the place starts again from there.
FILTER_FRAMES = 7
FILTER_JUMP_M = 0.02


class CubeFilter:
    """The object_state to send, from each picture's: the median of the newest sure ones, held where it
    was while the eyes are unsure of the cube (see CUBE_SURE, FILTER_FRAMES, FILTER_JUMP_M)."""

    def __init__(self) -> None:
        self._seen: list[list[float]] = []

    def reset(self) -> None:
        self._seen.clear()

    def state(self) -> list[float] | None:
        if not self._seen:
            return None
        seen = np.asarray(self._seen)
        centre = np.median(seen[:, :3], axis=0)
        quarter_turns = 4 * np.arctan2(seen[:, 5], seen[:, 6]) * 2  # each level quaternion's yaw, times 4
        yaw = math.atan2(float(np.median(np.sin(quarter_turns))), float(np.median(np.cos(quarter_turns)))) / 4
        return [*(float(value) for value in centre), 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2), *self._seen[-1][7:]]

    def add(self, seen: list[float], sure: float) -> list[float]:
        """The state to send after a picture whose object_state is `seen` and cube map's peak share `sure`."""
        if sure >= CUBE_SURE or not self._seen:
            now = self.state()
            if now is not None and math.dist(now[:3], seen[:3]) > FILTER_JUMP_M:
                self._seen.clear()
            self._seen = [*self._seen[-(FILTER_FRAMES - 1):], list(seen)]
        state = self.state()
        assert state is not None
        return state
