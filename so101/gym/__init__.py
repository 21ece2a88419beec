"""The cube_to_box task as a Gymnasium environment: `import so101.gym` registers `so101/CubeToBox-v0`.

    env = gymnasium.make("so101/CubeToBox-v0", body="mujoco", obs_type="all", camera_size=(320, 240))

`so101 eval` and `so101 demos` run the task through the dora dataflow, in lockstep; this is the same
task, bodies, frame and time limit behind Gymnasium's API (so101.gym.cube_to_box), for LeRobot's
`lerobot-eval` (so101.gym.lerobot_config), vector environments and RL libraries. The scripted expert
acts on it through so101.gym.expert. docs/loop/gym.md says how.
"""

from __future__ import annotations

import gymnasium

from so101.runtime.lockstep import DEFAULT_LOCKSTEP_FPS
from so101.tasks.episodes import DEFAULT_TIME_LIMIT_S, EpisodeClock

ENV_ID = "so101/CubeToBox-v0"
# `so101 eval`'s time limit in frames (750): gymnasium.make wraps the environment in a TimeLimit of these.
MAX_EPISODE_STEPS = EpisodeClock(DEFAULT_LOCKSTEP_FPS, DEFAULT_TIME_LIMIT_S).limit_frames

if ENV_ID not in gymnasium.registry:  # imported again (LeRobot's plugin loader, a reload): registered once
    gymnasium.register(id=ENV_ID, entry_point="so101.gym.cube_to_box:CubeToBoxEnv", max_episode_steps=MAX_EPISODE_STEPS)
