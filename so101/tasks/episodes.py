"""Episodes of a task, judged and scored: plain functions for `so101 eval`, `so101 demos` and their runner.

An episode runs from a reset until the task's success function holds (`succeeded`, from the
body's `task_status`) or its time limit passes. The score of N episodes is the fraction that
succeeded, with a 95% Wilson score interval: unlike the normal approximation it stays inside
0-100% and means something at 0 or N successes, which a small evaluation often has.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from typing import Iterable, Sequence

import numpy as np

# The normal quantile of a 95% two-sided interval.
Z_95 = 1.959963984540054
# Simulated seconds an episode may take before it fails: `so101 eval`'s, `so101 demos`' and the
# Gymnasium environment's (so101.gym) default, so that their scores mean the same.
DEFAULT_TIME_LIMIT_S = 30.0


@dataclass(frozen=True)
class Outcome:
    """One episode: its index among the run's, its layout's seed, whether and when it succeeded."""

    index: int
    seed: int
    success: bool
    frames: int  # frames the episode took, the last one included
    seconds: float  # simulated time: to success, or to the time limit
    attempts: int = 0  # grasps the driver tried, where it says (the expert); 0: not said
    kept: bool = False  # written into the dataset
    inference_ms: list[float] = field(default_factory=list)  # a policy's: each new action chunk's inference time

    def line(self) -> str:
        """One line per episode, as `so101 eval` and `so101 demos` print it."""
        what = f"success in {self.seconds:.2f} s" if self.success else f"failed (time limit, {self.seconds:.1f} s)"
        kept = ", kept" if self.kept else ""
        return f"episode {self.index} (seed {self.seed}): {what}, {self.frames} frames{kept}"

    def to_json(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> "Outcome":
        return cls(**json.loads(text))


def wilson_interval(successes: int, trials: int, z: float = Z_95) -> tuple[float, float]:
    """The Wilson score interval of a success rate (fractions, 0-1); (0, 1) for no trials."""
    if not 0 <= successes <= trials:
        raise ValueError(f"successes must be between 0 and the trials ({trials}), got {successes}")
    if trials == 0:
        return 0.0, 1.0
    rate = successes / trials
    denominator = 1 + z * z / trials
    centre = (rate + z * z / (2 * trials)) / denominator
    half = z * math.sqrt(rate * (1 - rate) / trials + z * z / (4 * trials * trials)) / denominator
    return max(0.0, centre - half), min(1.0, centre + half)


def score_line(outcomes: Sequence[Outcome]) -> str:
    """`success: K/N (P%, 95% CI lo–hi), mean time to success T s` (Wilson score interval)."""
    trials = len(outcomes)
    successes = sum(outcome.success for outcome in outcomes)
    low, high = wilson_interval(successes, trials)
    rate = 100.0 * successes / trials if trials else 0.0
    times = [outcome.seconds for outcome in outcomes if outcome.success]
    mean = f"{sum(times) / len(times):.2f} s" if times else "none (no success)"
    return (f"success: {successes}/{trials} ({rate:.0f}%, 95% CI {100 * low:.0f}–{100 * high:.0f}%, Wilson), "
            f"mean time to success {mean}")


def inference_line(outcomes: Sequence[Outcome]) -> str | None:
    """`inference: N action chunks, median M ms, 95th percentile P ms, longest L ms` over a
    policy's episodes (wall time on its device; in lockstep it costs no simulated time); None when
    no driver said (the expert, idle)."""
    times = [ms for outcome in outcomes for ms in outcome.inference_ms]
    if not times:
        return None
    median, high = np.percentile(times, [50, 95])
    return (f"inference: {len(times)} action chunks, median {median:.0f} ms, 95th percentile {high:.0f} ms, "
            f"longest {max(times):.0f} ms")


class EpisodeClock:
    """When an episode ends: at its first frame whose task_status says success, or once its frames
    reach the time limit (`fps` frames a simulated second)."""

    def __init__(self, fps: int, time_limit_s: float):
        self.fps = fps
        self.limit_frames = max(1, math.ceil(time_limit_s * fps))

    def ended(self, frame: int, success: bool) -> bool:
        return success or frame >= self.limit_frames

    def seconds(self, frame: int) -> float:
        return frame / self.fps


def seeds_for(first_seed: int, episodes: int) -> list[int]:
    """Episode i is laid out from seed first_seed + i."""
    return [first_seed + index for index in range(episodes)]


def split_seeds(seeds: Sequence[int], workers: int) -> list[list[int]]:
    """`seeds` in `workers` contiguous runs, as even as can be, in order (the merge keeps seed order)."""
    base, extra = divmod(len(seeds), workers)
    runs, start = [], 0
    for worker in range(workers):
        size = base + (1 if worker < extra else 0)
        runs.append(list(seeds[start:start + size]))
        start += size
    return [run for run in runs if run]


def read_outcomes(lines: Iterable[str]) -> tuple[list[Outcome], bool]:
    """The outcomes in a runner's results file, and whether it wrote its `done` line."""
    outcomes, done = [], False
    for line in lines:
        line = line.strip()
        if not line:
            continue
        if line == '"done"':
            done = True
            continue
        outcomes.append(Outcome.from_json(line))
    return outcomes, done
