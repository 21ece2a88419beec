"""Pictures for the eyes, drawn by the simulator with their answers: where the cube is in the picture
and in the world, its yaw and height, and where the box and the gripper's tip are in the picture.

The arm's poses and the objects' places come from demonstrations (a dataset with
`observation.environment_state`: `so101 demos`), so the eyes see the arm as it moves in a task,
the cube in the jaws included; half the pictures from frames whose cube still lies where it started.
Each picture draws its own looks (`varied` or `unseen`: so101.bodies.looks) from a seed of its own,
and a cube still lying where its episode put it moves to another layout's place half the time:
thousands of layouts for the price of a few hundred demonstrations. Held-out pictures draw their looks
and layouts from seeds the training pictures never draw.

Each picture is drawn with its episode's physics, as the dataset keeps it (its scenario's, `so101_episode_scenarios`):
its cube at its size, and the arm where it truly was while its calibration reported the recorded
angles. Its answers are what the picture shows (the tip where the arm truly was, the cube's height
above lying on the floor at its own size), but for `tip_xyz`, where the recorded angles put the tip:
what the perception node computes at run time, which knows no calibration's offsets.
"""

from __future__ import annotations

import contextlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import numpy.typing as npt
import pyarrow.parquet as pq

from so101.bodies.backdrop_pool import POOL
from so101.bodies.camera_file import CameraFile
from so101.bodies.physics import Physics, physics_from_metadata
from so101.dataset.features import ENVIRONMENT_KEY, STATE_KEY, from_lerobot
from so101.dataset.layout import INFO_PATH, SCENARIOS_KEY, episode_scenario
from so101.perception.estimate import BOX_POINT_HEIGHT_M
from so101.perception.geometry import view_of
from so101.tasks.cube_to_box import CUBE_TO_BOX
from so101.tasks.objects import cube_with, on_the_floor

# Looks seeds of training pictures are drawn from [LOOKS_SEED_BASE, 2 x LOOKS_SEED_BASE): far from any
# episode seed a score uses; held-out pictures' from the next span of as many, which training never draws.
LOOKS_SEED_BASE = 5_000_000
# Layouts a still cube moves to: [LAYOUT_SEED_BASE, 2 x LAYOUT_SEED_BASE), held-out pictures' the next span.
LAYOUT_SEED_BASE = 3_000_000
# A cube within this of where its episode put it still lies there (the arm has not touched it).
STILL_M = 0.002
STILL_SHARE = 0.5  # the pictures drawn from such frames, on top of their share of the rest


def yaw_of(quaternion_xyzw: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """The yaw (rad) of (N, 4) quaternions: the heading of their x axis in the floor's plane."""
    q = np.atleast_2d(np.asarray(quaternion_xyzw, dtype=float))
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    result: npt.NDArray[np.float64] = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return result


@dataclass(frozen=True)
class Frames:
    """A dataset's frames as the renderer takes them: the six angles (degrees) and the object state."""

    angles_deg: npt.NDArray[np.float64]
    object_state: npt.NDArray[np.float64]
    episode: npt.NDArray[np.int64]
    physics: dict[int, Physics | None] = field(default_factory=dict)  # by episode; none given: fixed

    def physics_of(self, frame: int) -> Physics | None:
        return self.physics.get(int(self.episode[frame]))

    @property
    def still(self) -> npt.NDArray[np.bool_]:
        """Frames whose cube lies where its episode's first frame had it."""
        first = {int(e): i for i, e in reversed(list(enumerate(self.episode)))}
        start = self.object_state[[first[int(e)] for e in self.episode], :3]
        moved: npt.NDArray[np.bool_] = np.linalg.norm(self.object_state[:, :3] - start, axis=1) < STILL_M
        return moved


def read_frames(dataset: Path) -> Frames:
    """The frames of a dataset with the objects' state (`so101 demos` without --observe)."""
    files = sorted((dataset / "data").glob("chunk-*/*.parquet"))
    if not files:
        raise ValueError(f"{dataset} has no data/chunk-*/*.parquet: give a dataset `so101 demos` made")
    tables = [pq.read_table(file, columns=[STATE_KEY, ENVIRONMENT_KEY, "episode_index"]) for file in files]
    if any(ENVIRONMENT_KEY not in table.column_names for table in tables):
        raise ValueError(f"{dataset} holds no {ENVIRONMENT_KEY}: make its demonstrations without --observe")
    state = np.concatenate([np.stack(table[STATE_KEY].to_numpy(zero_copy_only=False)) for table in tables])
    objects = np.concatenate([np.stack(table[ENVIRONMENT_KEY].to_numpy(zero_copy_only=False)) for table in tables])
    episode = np.concatenate([table["episode_index"].to_numpy() for table in tables])
    return Frames(from_lerobot(state), objects.astype(np.float64), episode.astype(np.int64), episode_physics(dataset))


def episode_physics(dataset: Path) -> dict[int, Physics | None]:
    """Each episode's physics as the dataset keeps it (a dataset from before varied physics: fixed)."""
    info = json.loads((dataset / INFO_PATH).read_text(encoding="utf-8"))
    kept = {index: episode_scenario(info, index).get("physics") for index in range(int(info.get("total_episodes", 0)))}
    try:
        return {index: physics_from_metadata(entry) for index, entry in kept.items() if entry is not None}
    except ValueError as error:
        raise ValueError(f"{dataset / INFO_PATH}: {SCENARIOS_KEY}: {error}") from None


def picture_seeds(held_out: bool) -> tuple[tuple[int, int], tuple[int, int]]:
    """The spans ([low, high)) the looks' and the moved layouts' seeds are drawn from: training pictures'
    or held-out ones', which never meet."""
    span = 2 if held_out else 1
    return ((span * LOOKS_SEED_BASE, (span + 1) * LOOKS_SEED_BASE),
            (span * LAYOUT_SEED_BASE, (span + 1) * LAYOUT_SEED_BASE))


def draw_pictures(frames: Frames, count: int, seed: int, size: tuple[int, int], looks: str,
                  progress: Callable[[int], None] = lambda done: None, held_out: bool = False,
                  poses: dict[str, CameraFile] | None = None, backdrops: dict[str, str] | None = None,
                  pool_share: float = 0.0) -> dict[str, np.ndarray]:
    """`count` front pictures at `size` (width, height) of frames drawn from `frames` by `seed`, each in
    looks of its own, with their answers (see the module's doc); `held_out`: looks and layouts that
    training pictures never draw. `poses` and `backdrops` (so101.bodies.scenario's): where the cameras
    stand, and the photos behind them. `pool_share`: where no front backdrop is given, that share of the
    pictures is drawn over the backdrop pool (so101.bodies.backdrop_pool), the others over the floor."""
    from so101.bodies.task_cameras import TaskCameras
    from so101.kinematics import Kinematics

    width, height = size
    draw = np.random.default_rng(seed)
    still = frames.still
    # Half the pictures from frames whose cube still lies where it started: where the policy reads it most
    # (its first plan, the approach), and where a cube may move to any layout's place.
    still_frames = np.flatnonzero(still)
    chosen = np.where(draw.random(count) < STILL_SHARE, still_frames[draw.integers(0, len(still_frames), count)],
                      draw.integers(0, len(frames.angles_deg), count))
    pictures = np.zeros((count, height, width, 3), dtype=np.uint8)
    cube_px, box_px, tip_px = np.zeros((count, 2)), np.zeros((count, 2)), np.zeros((count, 2))
    states, tips, cube_half = np.zeros((count, 10)), np.zeros((count, 3)), np.zeros(count)
    looks_seeds, layout_seeds = picture_seeds(held_out)
    pooled = pool_share > 0 and "front" not in (backdrops or {})
    with contextlib.ExitStack() as stack:
        plain = stack.enter_context(TaskCameras(CUBE_TO_BOX, log=lambda message: None, looks=looks, poses=poses,
                                                backdrops=backdrops))
        over_pool = stack.enter_context(TaskCameras(CUBE_TO_BOX, log=lambda message: None, looks=looks, poses=poses,
                                                    backdrops={**(backdrops or {}), "front": POOL})) if pooled else plain
        kinematics = stack.enter_context(Kinematics())
        for done, frame in enumerate(chosen):
            cameras = over_pool if pooled and draw.random() < pool_share else plain
            cameras.show_seed(int(draw.integers(*looks_seeds)))
            physics = frames.physics_of(frame)
            cameras.show_physics(physics)
            cube = cube_with(CUBE_TO_BOX.cube, physics)
            state = frames.object_state[frame].copy()
            if still[frame] and draw.random() < 0.5:
                layout = on_the_floor(CUBE_TO_BOX.layout(int(draw.integers(*layout_seeds))), cube)
                state[0:3], state[3:7] = layout.cube_xyz_m, layout.cube_quat_xyzw()
            reported_deg = frames.angles_deg[frame]
            true_deg = reported_deg if physics is None else np.array(physics.true_deg(reported_deg))
            picture, _ = cameras.draw(reported_deg, state, width, height, wrist=False)
            view = view_of(cameras.front_camera(), width, height)
            tips[done] = np.asarray(kinematics.tip_mm(reported_deg[:5])) / 1000.0
            pictures[done], states[done], cube_half[done] = picture, state, cube.half_size_m
            cube_px[done] = view.project([state[0:3]])[0]
            box_px[done] = view.project([[state[7], state[8], BOX_POINT_HEIGHT_M]])[0]
            tip_px[done] = view.project([np.asarray(kinematics.tip_mm(true_deg[:5])) / 1000.0])[0]
            progress(done + 1)
    return {"pictures": pictures, "cube_px": cube_px, "box_px": box_px, "tip_px": tip_px, "tip_xyz": tips,
            "object_state": states, "cube_yaw": yaw_of(states[:, 3:7]), "cube_half_m": cube_half,
            "size": np.array(size)}


def cube_half_m(drawn: dict[str, np.ndarray]) -> npt.NDArray[np.float64]:
    """Each picture's cube's half size: its episode's (pictures drawn before varied physics: the task's own)."""
    if "cube_half_m" in drawn:
        return np.asarray(drawn["cube_half_m"], dtype=float)
    return np.full(len(drawn["object_state"]), CUBE_TO_BOX.cube.half_size_m)


def yaw_mod_quarter(yaw_rad: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """A cube's yaw folded into [-45°, 45°): it looks the same every quarter turn."""
    half = math.pi / 4
    folded: npt.NDArray[np.float64] = (np.asarray(yaw_rad, dtype=float) + half) % (2 * half) - half
    return folded
