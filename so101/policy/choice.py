"""A policy folder chosen for a dataflow (`so101 eval --policy`, `so101 teleop --policy`), checked from
its config.json before anything starts (the node checks again as it loads): what it reads, the size
of the pictures it sees, the Python that runs it, and its joints' units (its training dataset's, which must
be degrees, as the body takes). A seeing recipe's folder (`so101 learn --sees`:
so101.perception.recipe) is chosen whole: its state policy, and the eyes that fill the policy's
object_state from the front picture (the perception node)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

from so101.bodies.camera_file import CameraFile
from so101.dataset.features import ENVIRONMENT_KEY, IMAGE_KEY
from so101.dataset.layout import DatasetError
from so101.dataset.units import DEGREES, UNITS_KEY, UnitsError
from so101.perception.recipe import Recipe, read_recipe
from so101.policy.environment import default_dir, dora_problem, python_in
from so101.tasks import task_named
from so101.policy.features import inputs_for, picture_size_of, read_policy_features, unscaled_inputs


@dataclass(frozen=True)
class ChosenPolicy:
    folder: Path
    python: Path
    inputs: tuple[str, ...]  # the body's outputs it reads
    picture_size: tuple[int, int] | None  # (width, height) of the cameras it sees; None: none
    unscaled: Mapping[str, str] = field(default_factory=dict)  # input feature -> its type, taken unscaled
    features: tuple[str, ...] = ()  # its input features, as its config.json names them
    recipe: Recipe | None = None  # a seeing recipe's: the eyes in front of it
    units_note: str = ""  # how its joints' units were known, where they could not be

    @property
    def body_pictures(self) -> tuple[tuple[str, ...], tuple[int, int] | None]:
        """The pictures the body (or its camera) must draw, and their size: the policy's own, or the eyes'."""
        if self.recipe is not None:
            return ("image",), self.recipe.eyes.size
        return (("image", "wrist_image"), self.picture_size) if self.picture_size else ((), None)

    def reads(self) -> str:
        """One line: what the policy reads, and where its object_state comes from."""
        parts = []
        for name in self.features:
            if name != ENVIRONMENT_KEY:
                parts.append(name)
            elif self.recipe is not None:
                parts.append(f"{name} (from the perception node, which sees {IMAGE_KEY} and the joints)")
            else:
                parts.append(f"{name} (the simulator's object_state, which a real arm does not have)")
        return "the policy reads: " + ", ".join(parts)

    def perception_env(self, lang: str) -> dict[str, str]:
        """The perception node's settings (so101.perception.settings.PerceptionSettings); {} without eyes."""
        if self.recipe is None:
            return {}
        return {"SO101_EYES_DIR": str(self.recipe.eyes_dir), "SO101_TASK": self.recipe.task, "SO101_LANG": lang}

    def notes(self, backdrops: Mapping[str, str] | None = None,
              camera_poses: Mapping[str, CameraFile] | None = None) -> list[str]:
        """What a user should know before scoring or driving with it, one line each; a recipe's eyes run over
        other `backdrops` or from other `camera_poses` than they were taught with, too."""
        elsewhere = [] if self.recipe is None else self.recipe.elsewhere(
            dict(backdrops or {}), {name: pose.as_dict() for name, pose in (camera_poses or {}).items()})
        return elsewhere + [f"note: the policy takes {name} unscaled (its config.json's normalization_mapping has no {kind}, "
                "as ACT's default): docs/loop/policy.md says what that costs and how --policy.normalization_mapping "
                "scales it" for name, kind in self.unscaled.items()] + ([self.units_note] if self.units_note else [])

    def env(self, task: str, device: str) -> dict[str, str]:
        """The policy node's settings (so101.policy.settings.PolicySettings)."""
        size = f"{self.picture_size[0]}x{self.picture_size[1]}" if self.picture_size else ""
        return {"SO101_POLICY_DIR": str(self.folder), "SO101_POLICY_DEVICE": device, "SO101_TASK": task,
                "SO101_LOCKSTEP_PICTURES": size}


def joint_units_note(policy_dir: Path) -> str:
    """Empty where the policy's training dataset (its train_config.json's) is here and its joints are degrees; a
    note where that dataset is not here to say; ValueError in one line where its joints are not degrees or
    cannot be known. The body takes degrees: a policy trained in LeRobot's normalized units would send them as
    degrees (so101.dataset.units)."""
    from so101.dataset.reader import Dataset

    try:
        root = json.loads((policy_dir / "train_config.json").read_text(encoding="utf-8"))["dataset"]["root"]
    except (OSError, ValueError, KeyError, TypeError):
        root = None
    if not root or not Path(root).is_dir():
        return (f"note: the policy's joints are taken as degrees: its training dataset ({root or 'not named'}) is "
                "not on this machine to say")
    try:
        units = Dataset.open(Path(root)).joint_units()
    except UnitsError:
        raise ValueError(f"the policy was trained on {root}, which does not say its joints' units, and its values "
                         f"could be degrees or LeRobot's normalized units: if degrees, say so in its meta/info.json "
                         f'("{UNITS_KEY}": "{DEGREES}")') from None
    except DatasetError as error:
        raise ValueError(f"the policy's training dataset: {error}") from None
    if units.units != DEGREES:
        raise ValueError(f"the policy was trained on {root}, whose joints are in LeRobot's normalized units: it would "
                         "send them to the arm as degrees; train it on a dataset in degrees")
    return ""


def choose_policy(folder: Path, python: Path | None, task: str | None, names_of_objects: tuple[str, ...],
                  python_elsewhere: bool = False) -> ChosenPolicy:
    """The policy in `folder`, run by `python` (default: so101 policy-env's), on a body that runs `task`
    (None: none) whose object_state has `names_of_objects`; ValueError in one line for a folder that is
    not a policy's, features the dataflow cannot give, or no Python to run it (none there, or one without the
    dataflow's dora-rs: the node could not even say what is wrong). `python_elsewhere`: the node runs on
    another machine of a cluster, and `python` is a path there, taken as written (absolute) and not checked
    here; the folder is read here, and must be at the same path there."""
    folder = folder.expanduser().resolve()
    recipe = read_recipe(folder)
    if recipe is not None:  # its eyes give the object_state, on a real arm too
        folder = recipe.policy_dir
        names_of_objects = names_of_objects or task_named(recipe.task).object_state_names
    inputs, outputs = read_policy_features(folder)
    if task is None and ENVIRONMENT_KEY in inputs and recipe is None:
        raise ValueError(f"the policy reads a task's objects ({ENVIRONMENT_KEY}): run it on a simulation with --task "
                         "cube_to_box (the real arm reports no objects)")
    picture_size = picture_size_of(inputs)
    needed = inputs_for(inputs, outputs, names_of_objects, picture_size)
    chosen = (python or python_in(default_dir())).expanduser()
    if python_elsewhere:
        if not chosen.is_absolute():
            raise ValueError(f"--policy-python {chosen} must be an absolute path on the policy's machine")
        return ChosenPolicy(folder, chosen, needed, picture_size, unscaled_inputs(folder), tuple(inputs), recipe,
                            joint_units_note(folder))
    if not chosen.exists():
        raise ValueError(f"{chosen} does not exist: make the policy environment with `so101 policy-env`, or give "
                         "--policy-python PY (a Python with LeRobot and dora-rs)")
    problem = dora_problem(chosen)
    if problem:
        raise ValueError(problem)
    return ChosenPolicy(folder, chosen.absolute(), needed, picture_size, unscaled_inputs(folder), tuple(inputs), recipe,
                        joint_units_note(folder))
