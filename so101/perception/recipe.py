"""A seeing recipe's folder, as `so101 learn --sees` writes it: eyes taught by the simulator (eyes/)
in front of a state policy (policy/, a LeRobot folder), and so101_recipe.json saying so. `so101 eval
--policy` and `so101 teleop --policy` take the folder whole and run both: the perception node turns
the front picture and the joints into object_state, and the policy reads that object_state instead
of the simulator's."""

from __future__ import annotations

import json
from dataclasses import dataclass
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
        task = str(json.loads((folder / RECIPE_FILE).read_text(encoding="utf-8"))["task"])
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise ValueError(f"{folder / RECIPE_FILE} is not a recipe file ({type(error).__name__}: {error})") from None
    recipe = Recipe(folder, read_eyes_facts(folder / EYES_DIR), task)
    if not (recipe.policy_dir / "config.json").is_file():
        raise ValueError(f"{folder} is a recipe without its policy ({POLICY_DIR}/config.json): "
                         "`so101 learn` did not finish; run it again to resume")
    return recipe


def write_recipe(folder: Path, facts: dict[str, object]) -> None:
    (folder / RECIPE_FILE).write_text(json.dumps(facts, indent=1) + "\n", encoding="utf-8")
