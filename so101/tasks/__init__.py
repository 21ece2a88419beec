"""Tasks for the simulated arm: what is on the floor, where it starts, and when it is done.

Each task's facts live in one module (`cube_to_box`); `TASKS` names them for `--task` and
`SO101_TASK`. The simulators build a task's scene from those facts
(so101.tasks.pybullet_scene, so101.tasks.mujoco_scene), which a task makes for the body it is
handed to (so101.bodies.protocol.SceneTask). Light: no simulator is imported here.
"""

from __future__ import annotations

from so101.task_cmd import RESET_WORD, parse_reset, parse_seed  # noqa: F401  (the task_cmd's words, named here too)
from so101.tasks.cube_to_box import CUBE_TO_BOX, CubeToBox

TASKS: dict[str, CubeToBox] = {CUBE_TO_BOX.name: CUBE_TO_BOX}


def task_named(name: str) -> CubeToBox:
    """The task called `name`; ValueError in one line, naming the tasks there are, otherwise."""
    try:
        return TASKS[name]
    except KeyError:
        raise ValueError(f"unknown task {name!r}; the tasks are: {', '.join(TASKS)}") from None


def task_for_setting(name: str, env_var: str = "SO101_TASK") -> CubeToBox | None:
    """The task a node's setting names (`SO101_TASK`), None where it names none; ValueError in one
    line, naming the setting and the tasks there are, otherwise."""
    if not name:
        return None
    try:
        return task_named(name)
    except ValueError as error:
        raise ValueError(f"{env_var}: {error}") from None
