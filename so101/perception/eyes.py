"""The eyes as the perception node runs them: a folder written by their training (`eyes.pt`, the
weights; `eyes.json`, the picture size and the camera they assume), one picture and the arm's joints
in, the task's object_state out. The network runs in PyTorch (the policy environment); what its maps
mean is so101.perception.estimate's."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import numpy.typing as npt

from so101.bodies.camera import TASK_FRONT_CAMERA, Camera
from so101.bodies.camera_file import CameraFile, orbit_of
from so101.perception.estimate import CubeFilter, Sighting, object_state, read_maps
from so101.perception.geometry import view_of
from so101.tasks.objects import SceneFacts

EYES_WEIGHTS = "eyes.pt"
EYES_FACTS = "eyes.json"


@dataclass(frozen=True)
class EyesFacts:
    """What eyes.json says: the pictures' size the eyes learned from, the camera whose geometry turns
    their pixels into places, and how they were trained (steps, pictures, their error on held-out ones)."""

    size: tuple[int, int]
    camera: Camera
    trained: dict[str, Any]

    def as_json(self) -> str:
        return json.dumps({"size": list(self.size), "camera": asdict(self.camera), "trained": self.trained}, indent=1) + "\n"


def read_eyes_facts(folder: Path) -> EyesFacts:
    """eyes.json of an eyes folder; ValueError in one line for a folder that holds no eyes."""
    if not (folder / EYES_WEIGHTS).is_file():
        raise ValueError(f"{folder} holds no {EYES_WEIGHTS}: give the folder `so101 learn` wrote")
    try:
        facts = json.loads((folder / EYES_FACTS).read_text(encoding="utf-8"))
        camera = facts["camera"]
        return EyesFacts((int(facts["size"][0]), int(facts["size"][1])),
                         Camera(tuple(float(v) for v in camera["target_xyz_m"]), float(camera["distance_m"]),  # type: ignore[arg-type]
                                float(camera["yaw_deg"]), float(camera["pitch_deg"]), float(camera["fov_deg"]),
                                float(camera.get("roll_deg", 0.0))),
                         dict(facts.get("trained") or {}))
    except (OSError, ValueError, KeyError, TypeError, IndexError) as error:
        raise ValueError(f"{folder / EYES_FACTS} is not an eyes' facts file ({type(error).__name__}: {error})") from None


def default_eyes_facts(size: tuple[int, int], trained: dict[str, Any]) -> EyesFacts:
    return EyesFacts(size, TASK_FRONT_CAMERA, trained)


class Eyes:
    """Loaded eyes: `see(picture, arm_deg)` -> (object_state, sighting), the cube's place the median of the
    newest sightings, held while its map is unsure (so101.perception.estimate.CubeFilter; `reset` forgets
    them: a new episode)."""

    def __init__(self, folder: Path, task: SceneFacts, threads: int = 1, front: CameraFile | None = None):
        import torch

        from so101.kinematics import Kinematics
        from so101.perception.net import EyesNet

        self.facts = read_eyes_facts(folder)
        torch.set_num_threads(threads)
        saved = torch.load(folder / EYES_WEIGHTS, map_location="cpu", weights_only=True)
        self._net = EyesNet()
        try:
            self._net.load_state_dict(saved["state_dict"])
        except (KeyError, RuntimeError) as error:
            raise ValueError(f"{folder / EYES_WEIGHTS} does not fit this project's eyes ({type(error).__name__})") from None
        self._net.eval()
        self._torch = torch
        self._kinematics = Kinematics()
        self._task = task
        # Where the front camera stands: a camera file's place (a fitted real camera), else the one they learned with.
        self.view = view_of(orbit_of(front) if front is not None else self.facts.camera, *self.facts.size)
        self._filter = CubeFilter()

    def reset(self) -> None:
        self._filter.reset()

    def see(self, picture: npt.NDArray[np.uint8], arm_deg: Sequence[float]) -> tuple[list[float], Sighting]:
        width, height = self.facts.size
        if picture.shape != (height, width, 3):
            raise ValueError(f"a picture of shape {picture.shape}: the eyes see {width}x{height}")
        with self._torch.inference_mode():
            maps = self._net(self._torch.from_numpy(np.ascontiguousarray(picture)).permute(2, 0, 1)[None])[0].numpy()
        sighting = read_maps(maps)
        tip_m = [coordinate / 1000.0 for coordinate in self._kinematics.tip_mm(list(arm_deg)[:5])]
        seen = object_state(sighting, self.view, self._task.cube, self._task.box, tip_m)
        return self._filter.add(seen, sighting.sure["cube"]), sighting

    def close(self) -> None:
        self._kinematics.close()
