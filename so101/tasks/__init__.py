"""Tasks for the simulated arm: what is on the floor, where it starts, and when it is done.

Each task's facts live in one module (`cube_to_box`); `TASKS` names them for `--task` and
`SO101_TASK`. The simulators build a task's scene from those facts
(so101.tasks.pybullet_scene, so101.tasks.mujoco_scene). Light: no simulator is imported here.
"""

from __future__ import annotations

from so101.tasks.cube_to_box import CUBE_TO_BOX, CubeToBox

TASKS: dict[str, CubeToBox] = {CUBE_TO_BOX.name: CUBE_TO_BOX}


def task_named(name: str) -> CubeToBox:
    """The task called `name`; ValueError in one line, naming the tasks there are, otherwise."""
    try:
        return TASKS[name]
    except KeyError:
        raise ValueError(f"unknown task {name!r}; the tasks are: {', '.join(TASKS)}") from None


def parse_seed(text: str) -> int:
    """A seed as typed (`--seed 7`, `reset 7`): a whole number >= 0; ValueError in one line otherwise."""
    try:
        seed = int(text.strip())
    except (ValueError, AttributeError):
        raise ValueError(f"a seed is a whole number >= 0, got {text!r}") from None
    if seed < 0:
        raise ValueError(f"a seed is a whole number >= 0, got {text!r}")
    return seed


RESET_WORD = "reset"


def parse_reset(text: str) -> int | None:
    """A `task_cmd` (the prompt's `reset [SEED]`): the seed asked for, or None for the next one;
    ValueError in one line for anything else."""
    words = text.split()
    if not words or words[0] != RESET_WORD or len(words) > 2:
        raise ValueError(f"expected `{RESET_WORD}` or `{RESET_WORD} SEED`, got {text!r}")
    return parse_seed(words[1]) if len(words) == 2 else None
