"""A seeing recipe's folder, as `so101 learn --sees` writes it: eyes taught by the simulator (eyes/)
in front of a state policy (policy/, a LeRobot folder), and so101_recipe.json saying so. `so101 eval
--policy` and `so101 teleop --policy` take the folder whole and run both: the perception node turns
the front picture and the joints into object_state, and the policy reads that object_state instead
of the simulator's."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from so101.perception.eyes import EyesFacts, read_eyes_facts

RECIPE_FILE = "so101_recipe.json"
EYES_DIR = "eyes"
POLICY_DIR = "policy"


@dataclass(frozen=True)
class Recipe:
    folder: Path
    eyes: EyesFacts
    task: str  # the task it learned, whose objects the eyes find
    # What the eyes were taught in beyond varied looks (so101 learn --backdrop, --camera-pose): camera -> photo, and
    # camera -> its camera file's fields; empty: the simulator's floor and cameras.
    backdrops: dict[str, str] = field(default_factory=dict)
    camera_poses: dict[str, dict] = field(default_factory=dict)
    pool_share: float = 0.0  # of the eyes' pictures drawn over the backdrop pool (so101.bodies.backdrop_pool)

    def elsewhere(self, backdrops: dict[str, str], camera_poses: dict[str, dict]) -> list[str]:
        """One line for each camera this run draws otherwise than the eyes were taught: another backdrop, or
        another pose (`camera_poses` as files' fields)."""
        lines, floor = [], "the simulator's floor"
        taught_floor = f"{floor} and the backdrop pool" if self.pool_share else floor
        for name in sorted(set(self.backdrops) | set(backdrops)):
            if self.backdrops.get(name) != backdrops.get(name):
                taught = self.backdrops.get(name) or (taught_floor if name == "front" else floor)
                lines.append(f"note: the eyes were taught over {taught} behind the {name} camera, and run over "
                             f"{backdrops.get(name) or floor}")
        for name in sorted(set(self.camera_poses) | set(camera_poses)):
            if self.camera_poses.get(name) != camera_poses.get(name):
                taught = "a camera file's pose" if name in self.camera_poses else "the simulator's own"
                drawn = "another file's pose" if name in camera_poses else "the simulator's own"
                lines.append(f"note: the eyes were taught from the {name} camera at {taught}, and this run draws it "
                             f"at {drawn}")
        return lines

    @property
    def eyes_dir(self) -> Path:
        return self.folder / EYES_DIR

    @property
    def policy_dir(self) -> Path:
        return self.folder / POLICY_DIR


def read_recipe(folder: Path) -> Recipe | None:
    """The recipe in `folder`, or None where the folder is not a recipe's (a plain policy folder);
    ValueError in one line for a recipe that is incomplete."""
    if not (folder / RECIPE_FILE).is_file():
        return None
    try:
        written = json.loads((folder / RECIPE_FILE).read_text(encoding="utf-8"))
        task = str(written["task"])
        backdrops, camera_poses = dict(written.get("backdrops", {})), dict(written.get("camera_poses", {}))
        pool_share = float(written.get("backdrop_pool_share", 0.0))
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as error:
        raise ValueError(f"{folder / RECIPE_FILE} is not a recipe file ({type(error).__name__}: {error})") from None
    recipe = Recipe(folder, read_eyes_facts(folder / EYES_DIR), task, backdrops, camera_poses, pool_share)
    if not (recipe.policy_dir / "config.json").is_file():
        raise ValueError(f"{folder} is a recipe without its policy ({POLICY_DIR}/config.json): "
                         "`so101 learn` did not finish; run it again to resume")
    return recipe


def write_recipe(folder: Path, facts: dict[str, object]) -> None:
    (folder / RECIPE_FILE).write_text(json.dumps(facts, indent=1) + "\n", encoding="utf-8")
