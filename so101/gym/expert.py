"""The scripted expert through the Gymnasium API: `ExpertPolicy`, its action for an environment's state.

    policy = ExpertPolicy()
    observation, info = env.reset(seed=1000)
    while True:
        observation, reward, terminated, truncated, info = env.step(policy(env))
        if terminated or truncated:
            break

It is the expert `so101 eval --expert` and `so101 demos` run in the dataflow (so101.tasks.expert):
a plan per episode from the layout's seed, played out on the frame's clock (frames / 25 s), reading
the arm's angles and the objects' poses, as nodes/expert.py reads them from a lockstep frame. It
reads them from the environment itself (`env.unwrapped`), so it acts on a single environment, not
a vector of them. Its action is in the environment's units (degrees, the gripper 0-100).

Scored from the command line, `python -m so101.gym.expert --body mujoco --seed 1000 --episodes 50`
prints a line per episode and `so101 eval`'s score line (success rate, Wilson interval).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any, Sequence

import gymnasium
import numpy as np
import numpy.typing as npt

from so101.bodies.registry import SIMULATED_BODIES
from so101.dataset.features import to_lerobot
from so101.gym import ENV_ID
from so101.gym.cube_to_box import CubeToBoxEnv
from so101.runtime.argtypes import whole_number
from so101.runtime.lockstep import DEFAULT_LOCKSTEP_FPS
from so101.tasks import CUBE_TO_BOX
from so101.tasks.episodes import Outcome, score_line, seeds_for
from so101.tasks.expert import Expert, planner_for


class ExpertPolicy:
    """`policy(env)`: the scripted expert's action (six float32 values) for the state of `env`, a
    CubeToBoxEnv or a wrapper of one. A new episode (a reset) gets a fresh plan from its layout's
    seed. `noise` and `misses` are `so101 demos --noise/--misses`. Close it when done (its kinematics)."""

    def __init__(self, noise: float = 0.0, misses: float = 0.0, assets_dir: str | None = None):
        self.noise, self.misses = noise, misses
        self.planner = planner_for(CUBE_TO_BOX, assets_dir)
        self.expert: Expert | None = None
        self._episode: tuple[int, int] | None = None  # (id of the environment, its episode) planned for

    def __call__(self, env: gymnasium.Env[Any, Any]) -> npt.NDArray[np.float32]:
        state = env.unwrapped
        if not isinstance(state, CubeToBoxEnv):
            raise TypeError(f"the expert acts on {ENV_ID}, not on {type(state).__name__}")
        if state.episode == 0:
            raise gymnasium.error.ResetNeeded("call reset before asking the expert")
        if self.expert is None or self._episode != (id(state), state.episode):
            self.expert = Expert(self.planner, noise=self.noise, seed=state.layout_seed, misses=self.misses)
            self._episode = (id(state), state.episode)
        targets_deg = self.expert.targets(state.frame / DEFAULT_LOCKSTEP_FPS, state.joint_angles_deg().tolist(),
                                          state.object_state().tolist())
        return to_lerobot(targets_deg)

    def close(self) -> None:
        self.planner.close()

    def __enter__(self) -> "ExpertPolicy":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def run_episode(env: gymnasium.Env[Any, Any], policy: ExpertPolicy, seed: int, index: int = 0) -> Outcome:
    """One episode of `policy` on `env` (a TimeLimit's: gymnasium.make's), laid out from `seed`, as an
    Outcome counted as so101 eval counts it (frames: the first one and one per step)."""
    env.reset(seed=seed)
    steps, success = 0, False
    while True:
        _, _, terminated, truncated, info = env.step(policy(env))
        steps += 1
        success = bool(info["is_success"])
        if terminated or truncated:
            break
    attempts = policy.expert.attempts if policy.expert is not None else 0
    return Outcome(index, seed, success, steps + 1, steps / DEFAULT_LOCKSTEP_FPS, attempts=attempts)


def score_expert(body: str, seeds: Sequence[int], show: Any = None) -> list[Outcome]:
    """The expert's episodes on `body`, one per seed in order; `show(outcome)` after each."""
    env = gymnasium.make(ENV_ID, body=body)
    outcomes = []
    try:
        with ExpertPolicy() as policy:
            for index, seed in enumerate(seeds):
                outcomes.append(run_episode(env, policy, seed, index))
                if show is not None:
                    show(outcomes[-1])
    finally:
        env.close()
    return outcomes


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m so101.gym.expert",
                                     description="score the scripted expert on so101/CubeToBox-v0, in this process")
    parser.add_argument("--body", choices=SIMULATED_BODIES, default="pybullet", help="the simulator (default pybullet)")
    parser.add_argument("--seed", type=whole_number(0, 2**31), default=1000, metavar="S",
                        help="episode i is laid out from seed S + i (default 1000)")
    parser.add_argument("--episodes", type=whole_number(1, 100_000), default=50, metavar="N",
                        help="how many episodes (default 50)")
    args = parser.parse_args(argv)
    outcomes = score_expert(args.body, seeds_for(args.seed, args.episodes),
                            show=lambda outcome: print(outcome.line(), flush=True))
    print(score_line(outcomes), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
