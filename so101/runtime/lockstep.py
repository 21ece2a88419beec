"""Lockstep: a simulated body that steps one control period per action, as fast as the machine allows.

In lockstep (SO101_LOCKSTEP_FPS > 0) a body has no timer. It publishes a frame, waits for a
`joint_cmd`, applies it, steps exactly 1/fps of simulated time, publishes the next frame,
and waits again. A frame is every output the body declares, each with the same tags in
its metadata (`frame_tags`): the episode (how many resets so far), the frame's index in
it, and the layout's seed. A `task_cmd` reset starts the next episode at frame 0. A
`joint_cmd` tagged for another frame (one sent for the episode before a reset) is not
applied; an untagged one applies to the frame now, and none applies after an episode's last
frame (SO101_EPISODE_FRAMES) or a frame whose task_status says success: the body holds still
until the reset, so an episode ends at the same frame however late the reset comes. A
`task_cmd` `again` publishes the frame now once more, for a receiver that lost part of it (the
runner asks after a silence). No wall clock is in the loop, so the same seed and the same
driver give the same episode, bit for bit, however loaded the machine.

Paced mode (the 4 ms timer) stays the default for people; lockstep is for `so101 demos`
and `so101 eval`. Light: nothing here imports a simulator or dora.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Generic, Mapping, Sequence, TypeVar

from so101.runtime.dataflow import TICK_PERIOD_S

# The metadata keys of a lockstep frame's outputs, and of a joint_cmd that answers one.
EPISODE_KEY = "episode"
FRAME_KEY = "frame"
SEED_KEY = "seed"
# A driver's joint_cmd with this key true is played but not written into a dataset: the expert's miss
# on purpose, whose recovery alone is a demonstration (so101.tasks.expert.Expert.rehearsing).
NOT_WRITTEN_KEY = "not_written"
# A policy's joint_cmd that took a new action chunk says how long its inference took, in ms (wall
# time: in lockstep it costs no simulated time); `so101 eval` sums them up.
INFERENCE_MS_KEY = "inference_ms"
# A task_cmd that asks a body in lockstep for the frame now once more: dora 1.1 loses a message now
# and then (dora-rs/dora#3428 reports it for lockstep), and a lockstep loop that lost one would wait for ever.
AGAIN_WORD = "again"
# The frame rate demos and eval use: 40 ms, ten physics steps of the 4 ms tick. LeRobot's
# recordings of the real arm are 30 fps, whose 33.3 ms is no whole number of steps.
DEFAULT_LOCKSTEP_FPS = 25


def steps_per_frame(fps: int, step_s: float = TICK_PERIOD_S) -> int:
    """Physics steps in one frame of `fps`; ValueError in one line where 1/fps is not a whole number of them."""
    if fps < 1:
        raise ValueError(f"a lockstep frame rate is a whole number of frames per second >= 1, got {fps}")
    steps = round(1.0 / (fps * step_s))
    if steps < 1 or abs(steps * step_s * fps - 1.0) > 1e-9:
        rates = ", ".join(str(rate) for rate in lockstep_rates(step_s))
        raise ValueError(f"{fps} fps is not a whole number of {step_s * 1000:g} ms physics steps a frame; "
                         f"lockstep takes {rates}")
    return steps


def lockstep_rates(step_s: float = TICK_PERIOD_S) -> list[int]:
    """The frame rates whose period is a whole number of physics steps."""
    per_second = round(1.0 / step_s)
    return [fps for fps in range(1, per_second + 1) if per_second % fps == 0]


@dataclass(frozen=True)
class FrameTag:
    """Which frame a message belongs to."""

    episode: int
    frame: int
    seed: int

    def metadata(self) -> dict[str, int]:
        return {EPISODE_KEY: self.episode, FRAME_KEY: self.frame, SEED_KEY: self.seed}


def frame_tag(metadata: Mapping[str, Any] | None) -> FrameTag | None:
    """The tag of a lockstep message, or None for one without (a paced body's, a typed command)."""
    metadata = metadata or {}
    try:
        return FrameTag(int(metadata[EPISODE_KEY]), int(metadata[FRAME_KEY]), int(metadata.get(SEED_KEY, -1)))
    except (KeyError, TypeError, ValueError):
        return None


def answers(command: FrameTag | None, now: FrameTag) -> bool:
    """Whether a joint_cmd tagged `command` is for the frame `now` (an untagged one always is)."""
    return command is None or (command.episode, command.frame) == (now.episode, now.frame)


class FrameParts:
    """A receiver's assembly of lockstep frames: the parts named `needed`, as they come, by frame.

    `add` returns the whole frame (name -> value) once its last part is in. Parts of different
    frames may interleave (a driver's answer to a frame before a reset comes after the next
    frame's parts), so each frame is kept apart; only the newest few are kept, as a frame left
    incomplete that long will not be completed.
    """

    KEPT = 8

    def __init__(self, needed: tuple[str, ...]):
        self.needed = needed
        self._frames: dict[FrameTag, dict[str, Any]] = {}

    def add(self, name: str, tag: FrameTag, value: Any) -> dict[str, Any] | None:
        if name not in self.needed:
            return None
        parts = self._frames.setdefault(tag, {})
        parts[name] = value
        if len(parts) == len(self.needed):
            return self._frames.pop(tag)
        while len(self._frames) > self.KEPT:
            del self._frames[next(iter(self._frames))]  # the oldest first: dicts keep their order
        return None


Answer = TypeVar("Answer")


class LastAnswer(Generic[Answer]):
    """A driver's answer to the last frame it answered. A frame sent again (after a loss) gets that
    same answer, and the driver's own state (a plan's clock, an action chunk) does not move on."""

    def __init__(self) -> None:
        self._tag: FrameTag | None = None
        self._answer: Answer | None = None

    def to(self, tag: FrameTag, compute: Callable[[], Answer]) -> Answer:
        """The answer to frame `tag`: `compute()`'s, or the one given before if `tag` was the last frame answered."""
        if tag != self._tag or self._answer is None:
            self._answer, self._tag = compute(), tag
        return self._answer
