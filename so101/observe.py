"""What a dataset's frames show a policy trained on them (`so101 demos --observe`, `so101 teleop
--observe`): the arm's joints always; the task's objects' exact poses, the simulator's, which no
real arm has; and each camera. A dataset without the poses trains a policy that sees. A plain
fact: the recorder's, the runner's and the commands' settings read it, and it imports no room.
"""

from __future__ import annotations

from dataclasses import dataclass

OBSERVABLE = ("state", "environment", "front", "wrist")
OBSERVE_HELP = ("what the frames show a policy, comma-separated from state,environment,front,wrist (default: all "
                "that the body has); state,front,wrist leaves the simulator's exact object poses out, as a real "
                "arm has none: a policy trained on it sees")


@dataclass(frozen=True)
class Observed:
    """What a dataset's frames show, beside the state (always) and the action: the task's
    objects' poses (`observation.environment_state`), the front and the wrist cameras."""

    environment: bool = True
    front: bool = True
    wrist: bool = True

    def __str__(self) -> str:
        return ",".join(name for name, shown in zip(OBSERVABLE, (True, self.environment, self.front, self.wrist)) if shown)

    def problem(self, task: bool, video: bool, why_no_video: str = "--no-video",
                cameras: tuple[str, ...] | None = None) -> str | None:
        """What asks for more than the body has, in one line; None when it has all of it. `cameras`: the
        real arm's (`front`, `wrist`), where a body has real ones; a task's scene is not needed for them."""
        if self.environment and not task:
            return "environment is a task's objects: it goes with --task"
        if cameras:
            missing = [name for name, shown in (("front", self.front), ("wrist", self.wrist))
                       if shown and name not in cameras]
            return f"{missing[0]} is a camera not given: add --camera {missing[0]}=SOURCE" if missing else None
        if (self.front or self.wrist) and not video:
            return f"front and wrist are the cameras, and there are none here ({why_no_video})"
        if self.wrist and not task:
            return "the wrist camera is drawn for a task's episodes: wrist goes with --task"
        return None


ALL_OBSERVED = Observed()
OBSERVE_ENV_VAR = "SO101_OBSERVE"


def parse_observed(text: str) -> Observed:
    """`state,front,wrist` and the like -> Observed; ValueError in one line for a name not in
    OBSERVABLE, a name twice, or a list without state (the frames always hold the joints)."""
    names = [name.strip() for name in text.split(",")]
    unknown = [name for name in names if name not in OBSERVABLE]
    why = (f"{unknown[0]!r} is not something the frames can show" if unknown
           else "a name is given twice" if len(set(names)) != len(names)
           else "state is always shown (the arm's joints)" if "state" not in names else None)
    if why:
        raise ValueError(f"{why}: give a comma-separated list of {', '.join(OBSERVABLE)} with state in it, "
                         "e.g. state,front,wrist")
    return Observed(*(name in names for name in OBSERVABLE[1:]))


def observed_for(task: bool, video: bool, cameras: tuple[str, ...] = ()) -> Observed:
    """All that a body has: the objects with a task, the front camera with video, the wrist with both;
    with real `cameras`, those given."""
    if cameras:
        return Observed(environment=task, front="front" in cameras, wrist="wrist" in cameras)
    return Observed(environment=task, front=video, wrist=task and video)
