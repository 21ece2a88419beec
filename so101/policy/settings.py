"""The policy node's settings (nodes/policy.py): environment variables, each declared once
(so101/runtime/settings.py says how) and read once when the node starts. Light: the standard
library and this project's plain modules, as the policy's own Python imports them."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

from so101.cameras.sources import CAMERA_SILENT_S, parse_real_cameras
from so101.lang import DEFAULT_LANGUAGE, ENV_VAR as LANG_ENV_VAR, language_from_environ
from so101.runtime.argtypes import parsed_by
from so101.runtime.settings import (
    EnvironSettings, Setting, read_image_size, read_parsed, read_stripped_text, read_threads, setting,
)
from so101.tasks import task_named


def read_policy_dir(environ: Mapping[str, str], declared_setting: Setting) -> Path:
    return Path(read_stripped_text(environ, declared_setting)).expanduser()


def read_task_name(environ: Mapping[str, str], declared_setting: Setting) -> str:
    name = read_stripped_text(environ, declared_setting)
    try:
        task_named(name)
    except ValueError as error:
        raise ValueError(f"{declared_setting.env_var}: {error}") from None
    return name


def checked_device(device: str) -> str:
    """`device` if torch knows its kind; ValueError in one line otherwise."""
    if device.split(":")[0] not in ("cpu", "cuda", "mps"):
        raise ValueError(f"{device!r} is not a torch device: cpu, cuda (or cuda:N) or mps")
    return device


def read_device(environ: Mapping[str, str], declared_setting: Setting) -> str:
    try:
        return checked_device(read_stripped_text(environ, declared_setting))
    except ValueError as error:
        raise ValueError(f"{declared_setting.env_var}: {error}") from None


@dataclass(frozen=True)
class PolicySettings(EnvironSettings):
    """The policy node's (nodes/policy.py)."""

    policy_dir: Path = setting(
        "SO101_POLICY_DIR", "", "the policy's folder as LeRobot's `lerobot-train` writes it "
        "(`.../checkpoints/last/pretrained_model`: config, weights, pre- and post-processors)", read_policy_dir,
        required="(so101 eval --policy DIR, or the dataflow's env:) to a trained policy's folder")
    device: str = setting("SO101_POLICY_DEVICE", "cpu", "the torch device the policy runs on: cpu, cuda or mps",
                          read_device)
    task: str = setting("SO101_TASK", "cube_to_box", "the task the policy performs: its objects' poses and its "
                        "instruction", read_task_name)
    threads: int = setting(
        "SO101_POLICY_THREADS", "1", "PyTorch's threads for inference on the CPU: the body, the camera and the "
        "episodes' runner share the cores, and PyTorch's threads that outnumber the free cores wait on each other "
        "(docs/experiments/seeing-on-a-cpu.md)", read_threads)
    image_size: tuple[int, int] | None = setting(
        "SO101_LOCKSTEP_PICTURES", "", "WIDTHxHEIGHT of the body's pictures, for a policy that sees them; "
        "empty = none", read_image_size)
    real_cameras: tuple[str, ...] = setting(
        "SO101_POLICY_CAMERAS", "", "the real cameras the policy sees (`front`, `wrist`; nodes/real_camera.py): one "
        f"that sends no picture for {CAMERA_SILENT_S:g} s stops its drive; empty = a simulation's camera, which draws "
        "only when something moved", read_parsed(parse_real_cameras))
    lang: str = setting(LANG_ENV_VAR, DEFAULT_LANGUAGE, "log language, `zh` or `en`",
                        lambda environ, declared_setting: language_from_environ(environ))


torch_device = parsed_by(checked_device)  # an argparse `type` for a torch device
