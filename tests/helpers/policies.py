"""The policy environment and a tiny policy that sees, as session fixtures: conftest.py registers them for
every module (the policy at the prompt of a simulation, tests/test_policy.py; on the emulated real arm with
file cameras, tests/test_real_cameras.py), so lerobot-train makes the policy once a session."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

SEEN_SIZE = (32, 24)  # the tiny policy that sees: its pictures' (width, height)


@pytest.fixture(scope="session")
def policy_python() -> Path:
    """The policy environment's Python ($SO101_POLICY_PYTHON, else so101 policy-env's default), checked;
    the tests that need it are skipped, saying why, where there is none."""
    from so101.policy.environment import PolicyEnvError, check, default_dir, python_in

    python = Path(os.environ.get("SO101_POLICY_PYTHON") or python_in(default_dir()))
    try:
        return check(python).python
    except PolicyEnvError as error:
        pytest.skip(f"no policy environment, so nothing here runs in LeRobot itself (a policy, its loader): {error}")


@pytest.fixture(scope="session")
def seeing_policy(policy_python, tmp_path_factory) -> Path:
    """A tiny ACT that sees: the front and wrist cameras at 32x24 and the joints, no
    observation.environment_state, as `so101 demos --observe state,front,wrist` datasets train.
    Made here by lerobot-train, 2 steps on 2 episodes of random pictures, because its ResNet-18
    alone weighs 45 MB, too much to keep in tests/data."""
    from so101.dataset.features import (
        ACTION_KEY, IMAGE_KEY, REWARD_KEY, STATE_KEY, SUCCESS_KEY, WRIST_IMAGE_KEY, to_lerobot, video_keys_and_sizes,
    )
    from so101.dataset.writer import DatasetWriter
    from so101.observe import parse_observed
    from so101.tasks import CUBE_TO_BOX

    root, out = tmp_path_factory.mktemp("seen") / "dataset", tmp_path_factory.mktemp("seeing") / "train"
    observed = parse_observed("state,front,wrist")
    pictures = np.random.default_rng(0)
    width, height = SEEN_SIZE
    with DatasetWriter.open(root, 25, video_keys_and_sizes(SEEN_SIZE, True, observed),
                            environment_names=CUBE_TO_BOX.object_state_names, environment_state=False) as writer:
        for _ in range(2):
            episode = writer.start_episode(CUBE_TO_BOX.instruction)
            for i in range(30):
                state = to_lerobot([i, -i, 2 * i, 0.5 * i, 0.0, 20.0])
                episode.add_frame({STATE_KEY: state, ACTION_KEY: state + 1.0, REWARD_KEY: np.zeros(1, np.float32),
                                   SUCCESS_KEY: np.array([False]),
                                   **{key: pictures.integers(0, 256, (height, width, 3), dtype=np.uint8)
                                      for key in (IMAGE_KEY, WRIST_IMAGE_KEY)}})
            episode.save()
    trainer = policy_python.parent / "lerobot-train"
    done = subprocess.run([str(trainer), "--dataset.repo_id=local/seen", f"--dataset.root={root}",
                           "--dataset.video_backend=pyav", "--policy.type=act", "--policy.device=cpu",
                           "--policy.push_to_hub=false", "--policy.pretrained_backbone_weights=null",
                           "--policy.dim_model=32", "--policy.n_heads=2", "--policy.dim_feedforward=64",
                           "--policy.n_encoder_layers=1", "--policy.n_decoder_layers=1", "--policy.use_vae=false",
                           "--policy.chunk_size=10", "--policy.n_action_steps=10", "--steps=2", "--batch_size=2",
                           "--save_freq=2", "--num_workers=0", "--seed=1", "--wandb.enable=false", f"--output_dir={out}"],
                          capture_output=True, text=True, timeout=600, env={**os.environ, "HF_HUB_OFFLINE": "1"})
    assert done.returncode == 0, done.stderr[-3000:]
    return out / "checkpoints" / "last" / "pretrained_model"


RECIPE_EYES_SIZE = (32, 24)  # the tiny recipe's eyes: their pictures' (width, height)


@pytest.fixture(scope="session")
def seeing_recipe(policy_python, tmp_path_factory) -> Path:
    """A tiny seeing recipe, as `so101 learn --sees` writes one: tests/data/policy_act_tiny as its state
    policy, and eyes of untrained weights that see 32x24 pictures (made in the policy environment, where
    PyTorch is). It covers the wiring: the eyes' object_state, not the simulator's, reaches the policy."""
    import shutil

    from so101.perception.eyes import EYES_FACTS, default_eyes_facts
    from so101.perception.recipe import EYES_DIR, POLICY_DIR, write_recipe
    from so101.runtime.dataflow import ROOT

    folder = tmp_path_factory.mktemp("recipe")
    shutil.copytree(ROOT / "tests" / "data" / "policy_act_tiny", folder / POLICY_DIR)
    (folder / EYES_DIR).mkdir()
    made = subprocess.run([str(policy_python), "-c", "import sys, torch; from so101.perception.net import EyesNet; "
                           "torch.manual_seed(0); torch.save({'state_dict': EyesNet().state_dict()}, sys.argv[1])",
                           str(folder / EYES_DIR / "eyes.pt")], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert made.returncode == 0, made.stderr[-2000:]
    (folder / EYES_DIR / EYES_FACTS).write_text(default_eyes_facts(RECIPE_EYES_SIZE, {"steps": 0}).as_json())
    write_recipe(folder, {"recipe": "eyes + state policy", "task": "cube_to_box"})
    return folder
