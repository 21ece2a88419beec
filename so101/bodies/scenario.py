"""What an episode looks like and how it behaves: one value, from the command line to every node.

A task's episode is laid out from its seed. Four things vary with it beyond the layout:
- its pictures' looks (so101.bodies.looks: `fixed`, `varied`, `unseen`, which also draws the front
  camera's backdrop from the pool held out of the eyes' pictures where none is given);
- where its simulated cameras stand (so101.bodies.episode_cameras, from camera files: `--camera-pose NAME=FILE`);
- its physics (so101.bodies.physics: `fixed`, `varied`, or a ranges file's ranges);
- a photo of the workspace behind each camera's scene (so101.bodies.backdrop: `--backdrop NAME=IMAGE`).

A `Scenario` holds the four as a run asks for them. It travels whole: one environment variable
(`SCENARIO_ENV_VAR`, JSON, so that a node on another machine needs no ranges file) to the body, the
camera, the recorder, the episodes' runner and the perception node; a backdrop travels by its path,
which must be there on the node's machine. Each episode's are drawn from its seed (`metadata`), and a
dataset keeps them under one key by episode (so101.dataset.layout.SCENARIOS_KEY).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

from so101.bodies.backdrop import BackdropError, Placement, backdrop_photos, placement_for
from so101.bodies.backdrop_pool import with_unseen_pool
from so101.bodies.camera_file import CameraFile, CameraFileError, parse_camera_poses
from so101.bodies.episode_cameras import cameras_metadata
from so101.bodies.looks import DEFAULT_LOOKS, LOOKS_CHOICES, looks_metadata
from so101.bodies.physics import DEFAULT_PHYSICS, PhysicsError, physics_metadata, physics_mode

SCENARIO_ENV_VAR = "SO101_SCENARIO"
SCENARIO_HELP = ("what a task's episodes look like and how they behave, JSON: `looks` (fixed, varied or unseen), "
                 "`camera_poses` (a camera's name to its camera file's fields), `physics` (fixed, varied or a "
                 "ranges object) and `backdrops` (a camera's name to a photo or a folder of them); each left out is "
                 "the default (so101/bodies/scenario.py); empty = all defaults")
FIELDS = ("looks", "camera_poses", "physics", "backdrops")


@dataclass(frozen=True)
class Scenario:
    """A run's looks, camera poses, physics and backdrops, as asked for; each episode's are drawn from its seed."""

    looks: str = DEFAULT_LOOKS
    camera_poses: dict[str, CameraFile] = field(default_factory=dict)
    physics: str = DEFAULT_PHYSICS  # as physics_mode gives it: fixed, varied, or the ranges as JSON text
    backdrops: dict[str, str] = field(default_factory=dict)  # a camera's name -> a photo, or a folder of them

    def __post_init__(self) -> None:
        object.__setattr__(self, "backdrops", with_unseen_pool(self.looks, self.backdrops))

    def text(self) -> str:
        """This scenario as nodes are told it: JSON of what differs from the defaults ("" for none)."""
        given: dict[str, Any] = {}
        if self.looks != DEFAULT_LOOKS:
            given["looks"] = self.looks
        if self.camera_poses:
            given["camera_poses"] = {name: pose.as_dict() for name, pose in self.camera_poses.items()}
        if self.physics != DEFAULT_PHYSICS:
            given["physics"] = json.loads(self.physics) if self.physics.startswith("{") else self.physics
        if self.backdrops:
            given["backdrops"] = dict(self.backdrops)
        return json.dumps(given, separators=(",", ":"), sort_keys=True) if given else ""

    def env(self) -> dict[str, str]:
        """What a node is told: nothing for the defaults."""
        text = self.text()
        return {SCENARIO_ENV_VAR: text} if text else {}

    def metadata(self, seed: int, cameras: tuple[str, ...] = (), size: tuple[int, int] | None = None) -> dict[str, object]:
        """What a dataset keeps of episode seed `seed`: its physics, and where it has pictures from `cameras`
        (at `size`), their looks, where those cameras stood and their backdrops, as drawn."""
        kept: dict[str, object] = {"physics": physics_metadata(self.physics, seed)}
        if cameras and size is not None:
            kept["looks"] = looks_metadata(self.looks, seed)
            kept["cameras"] = cameras_metadata(self.camera_poses, self.looks, seed, cameras, size)
            drawn = {name: self.placement(name, seed).as_metadata() for name in cameras if name in self.backdrops}
            if drawn:
                kept["backdrops"] = drawn
        return kept

    def placement(self, camera: str, seed: int) -> Placement:
        """Episode seed `seed`'s backdrop behind `camera` (it has one: `camera in self.backdrops`)."""
        return placement_for(self.backdrops[camera], seed, varied=self.looks != DEFAULT_LOOKS)


def parse_scenario(text: str) -> Scenario:
    """SCENARIO_ENV_VAR as a node reads it; ValueError in one line for anything else."""
    if not text.strip():
        return Scenario()
    try:
        given = json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f"a scenario is JSON ({error.msg})") from None
    if not isinstance(given, dict):
        raise ValueError(f"a scenario is a JSON object of {', '.join(FIELDS)}")
    unknown = sorted(set(given) - set(FIELDS))
    if unknown:
        raise ValueError(f"a scenario has no {unknown[0]!r}: it holds {', '.join(FIELDS)}")
    looks = given.get("looks", DEFAULT_LOOKS)
    if looks not in LOOKS_CHOICES:
        raise ValueError(f"a scenario's looks are one of {', '.join(LOOKS_CHOICES)}, not {looks!r}")
    physics = given.get("physics", DEFAULT_PHYSICS)
    backdrops = given.get("backdrops", {})
    if not isinstance(backdrops, dict) or not all(isinstance(path, str) for path in backdrops.values()):
        raise ValueError("a scenario's backdrops map a camera's name to a photo's path, or a folder's")
    try:
        poses = parse_camera_poses(json.dumps(given.get("camera_poses", {})))
        mode = physics_mode(json.dumps(physics) if isinstance(physics, dict) else str(physics))
        for path in backdrops.values():
            backdrop_photos(path)
    except (CameraFileError, PhysicsError, BackdropError) as error:
        raise ValueError(f"the scenario: {error}") from None
    return Scenario(looks, poses, mode, dict(backdrops))


class ReadsScenario:
    """For a node's settings that read the scenario (`scenario`): its parts by name."""

    scenario: Scenario

    @property
    def looks(self) -> str:
        return self.scenario.looks

    @property
    def camera_poses(self) -> dict[str, CameraFile]:
        return self.scenario.camera_poses

    @property
    def physics(self) -> str:
        return self.scenario.physics
