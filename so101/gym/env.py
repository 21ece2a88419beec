"""EnvHub's `env.py`: `make_env(n_envs, use_async_envs)`, as LeRobot 0.4.4's hub loader calls it.

LeRobot (0.4.1 and later) loads a Hub repository's `env.py` by its path and calls its `make_env`
(lerobot.envs.factory.make_env("USER/REPO", trust_remote_code=True)); this is that file for
so101/CubeToBox-v0: put it at a repository's root (or name it, "USER/REPO@REVISION:so101/gym/env.py")
where the Python that loads it has this project importable (`so101 policy-env` links the checkout).
It returns {"so101_cube_to_box": {0: vector}}, a vector environment of `n_envs` in LeRobot's own
auto-reset mode (SAME_STEP: a finished episode's success is in info["final_info"]).
"""

from __future__ import annotations

from typing import Any

import gymnasium

from so101.gym import ENV_ID

SUITE = "so101_cube_to_box"  # the suite's name in LeRobot's results: the EnvConfig's type (so101.gym.lerobot_config)


def make_env(n_envs: int = 1, use_async_envs: bool = False, cfg: Any = None,
             **gym_kwargs: Any) -> dict[str, dict[int, gymnasium.vector.VectorEnv]]:
    """`n_envs` environments in one vector (processes of their own with `use_async_envs`), each made with
    `gym_kwargs` (body, obs_type, camera_size, looks, camera_pose, physics), or with those of `cfg`, an EnvConfig LeRobot passes."""
    if not isinstance(n_envs, int) or isinstance(n_envs, bool) or n_envs < 1:
        raise ValueError(f"n_envs={n_envs!r} is not a whole number of environments >= 1")
    kwargs = {**(getattr(cfg, "gym_kwargs", None) or {}), **gym_kwargs}
    vector = gymnasium.make_vec(ENV_ID, num_envs=n_envs, vectorization_mode="async" if use_async_envs else "sync",
                                vector_kwargs={"autoreset_mode": gymnasium.vector.AutoresetMode.SAME_STEP}, **kwargs)
    return {SUITE: {0: vector}}
