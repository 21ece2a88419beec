"""The environment as LeRobot 0.4.4 knows one: an `EnvConfig` registered as `so101_cube_to_box`.

    lerobot-eval --policy.path=DIR --env.type=so101_cube_to_box --env.discover_packages_path=so101.gym

`--env.discover_packages_path=so101.gym` has LeRobot import so101.gym and each of its modules, this
one among them: it registers the config, so101.gym the Gymnasium id. lerobot-eval then makes a vector
of `gymnasium.make(gym_id, **gym_kwargs)` and maps the observation's `agent_pos`,
`environment_state` and `pixels/<camera>` to `observation.state`, `observation.environment_state`
and `observation.images.<camera>`, the names `so101 demos` writes, so a policy trained on its
datasets reads what it learned from. `--env.obs_type` says what the environment observes: `state`
(default: a state-only policy), `pixels_agent_pos` (a policy that sees) or `all`.

Only LeRobot's own Python imports this module (the policy environment, `so101 policy-env`): the
project's imports none of LeRobot, and mypy reads LeRobot as unknown there.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_IMAGES, OBS_STATE

from so101.gym import ENV_ID, MAX_EPISODE_STEPS
from so101.gym.spaces import CAMERA_NAMES, DEFAULT_CAMERA_SIZE, check_obs_type, observes_objects, sees
from so101.robot import ACTUATED_JOINTS
from so101.runtime.lockstep import DEFAULT_LOCKSTEP_FPS
from so101.tasks import CUBE_TO_BOX

ENV_TYPE = "so101_cube_to_box"


@EnvConfig.register_subclass(ENV_TYPE)
@dataclass
class SO101CubeToBoxEnv(EnvConfig):
    """`--env.type=so101_cube_to_box`: the fields are `--env.<field>` options of lerobot-eval."""

    task: str | None = ENV_ID.split("/")[1]  # as LeRobot's configs name the Gymnasium task
    fps: int = DEFAULT_LOCKSTEP_FPS
    episode_length: int = MAX_EPISODE_STEPS  # so101 eval's time limit, in frames
    body: str = "pybullet"
    obs_type: str = "state"
    observation_width: int = DEFAULT_CAMERA_SIZE[0]
    observation_height: int = DEFAULT_CAMERA_SIZE[1]
    looks: str = "fixed"
    camera_pose: str = ""  # "front=FILE[,wrist=FILE]": the simulated cameras drawn from camera files
    physics: str = "fixed"  # "varied", or a JSON file of ranges: each layout's physics drawn from its seed
    backdrop: str = ""  # "front=IMAGE[,wrist=IMAGE]": a photo of the workspace behind a camera's scene
    render_mode: str = "rgb_array"
    features: dict[str, PolicyFeature] = field(default_factory=lambda: {
        ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(len(ACTUATED_JOINTS),))})
    features_map: dict[str, str] = field(default_factory=lambda: {
        ACTION: ACTION, "agent_pos": OBS_STATE, "environment_state": OBS_ENV_STATE,
        **{f"pixels/{camera}": f"{OBS_IMAGES}.{camera}" for camera in CAMERA_NAMES}})

    def __post_init__(self) -> None:
        check_obs_type(self.obs_type)
        self.features["agent_pos"] = PolicyFeature(type=FeatureType.STATE, shape=(len(ACTUATED_JOINTS),))
        if observes_objects(self.obs_type):
            self.features["environment_state"] = PolicyFeature(type=FeatureType.ENV,
                                                               shape=(len(CUBE_TO_BOX.object_state_names),))
        if sees(self.obs_type):
            for camera in CAMERA_NAMES:
                self.features[f"pixels/{camera}"] = PolicyFeature(
                    type=FeatureType.VISUAL, shape=(self.observation_height, self.observation_width, 3))

    @property
    def package_name(self) -> str:
        return "so101.gym"  # what LeRobot imports where gym_id is not registered yet

    @property
    def gym_id(self) -> str:
        return ENV_ID

    @property
    def gym_kwargs(self) -> dict:
        return {"body": self.body, "obs_type": self.obs_type, "looks": self.looks, "camera_pose": self.camera_pose,
                "physics": self.physics, "backdrop": self.backdrop,
                "render_mode": self.render_mode,
                "camera_size": (self.observation_width, self.observation_height),
                "max_episode_steps": self.episode_length}
