"""A trained LeRobot policy, loaded in this process: LeRobot's factory reads its folder as `lerobot-train`
writes it (config, weights, pre- and post-processors), so any policy type LeRobot knows loads. The policy
node (nodes/policy.py) drives with it; the expert node learning from it (DAgger: `so101 demos --learner`) lets
it drive before taking over. LeRobot and torch are imported here only, in the policy environment's Python."""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from so101.dataset.features import ROBOT_TYPE


class PolicyFailed(Exception):
    """The policy cannot be loaded or run; str() is one line for the user."""


class LoadedPolicy:
    """A LeRobot policy folder, loaded: its features, and one action per observation."""

    def __init__(self, folder: Path, device: str, instruction: str, threads: int | None = None):
        if not folder.is_dir():
            raise PolicyFailed(f"{folder} is not a folder: give a trained policy's folder "
                               "(.../checkpoints/last/pretrained_model)")
        if not (folder / "config.json").is_file():
            raise PolicyFailed(f"{folder} has no config.json: it is not a policy folder as lerobot-train writes it "
                               "(.../checkpoints/last/pretrained_model)")
        try:
            import torch
            from lerobot.configs.policies import PreTrainedConfig
            from lerobot.policies.factory import get_policy_class, make_pre_post_processors
            from lerobot.policies.utils import prepare_observation_for_inference
        except Exception as error:  # noqa: BLE001 (any import failure is the one line a user needs)
            raise PolicyFailed(f"LeRobot does not import in {sys.executable} ({type(error).__name__}: {error}): "
                               "run the node with a policy environment's Python (so101 policy-env)") from None
        if threads is not None:
            torch.set_num_threads(threads)
        try:
            config = PreTrainedConfig.from_pretrained(str(folder))
            config.device = device
            self.policy = get_policy_class(config.type).from_pretrained(str(folder), config=config)
            self.policy.eval()
            self.preprocess, self.postprocess = make_pre_post_processors(
                config, pretrained_path=str(folder), preprocessor_overrides={"device_processor": {"device": device}})
        except Exception as error:  # noqa: BLE001 (a folder LeRobot cannot load: one line, whatever LeRobot raised)
            raise PolicyFailed(f"LeRobot cannot load the policy in {folder}: {type(error).__name__}: {error}") from None
        self.kind = config.type
        self.input_shapes = {name: tuple(feature.shape) for name, feature in config.input_features.items()}
        self.output_shapes = {name: tuple(feature.shape) for name, feature in config.output_features.items()}
        self._torch, self._prepare = torch, prepare_observation_for_inference
        self._device, self._instruction = torch.device(device), instruction

    def reset(self) -> None:
        """A new episode: the action chunk and any history go."""
        self.policy.reset()

    def act(self, values: dict[str, np.ndarray]) -> tuple[np.ndarray, float | None]:
        """The next action: the policy's own choice of when to predict a new chunk (select_action); and
        when it took a new one, how long that took, in ms (None when the action came from the chunk)."""
        # ACT plays a chunk out of its queue; a policy without one infers at every call.
        queue = getattr(self.policy, "_action_queue", None)
        inferring = queue is None or len(queue) == 0
        started_s = time.perf_counter()
        action = self._run(self.policy.select_action, values)
        return action, (time.perf_counter() - started_s) * 1000.0 if inferring else None

    def chunk(self, values: dict[str, np.ndarray]) -> np.ndarray:
        """A whole action chunk for this observation (chunk x 6), the policy's history untouched: for
        checks against a dataset (tools/grasp_error.py)."""
        return self._run(self.policy.predict_action_chunk, values)

    def _run(self, predict: Any, values: dict[str, np.ndarray]) -> np.ndarray:
        with self._torch.inference_mode():
            batch = self._prepare(dict(values), self._device, self._instruction, ROBOT_TYPE)
            action = self.postprocess(predict(self.preprocess(batch)))
        return action.squeeze(0).to("cpu").numpy()
