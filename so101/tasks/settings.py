"""The task nodes' settings (nodes/expert.py, nodes/episodes.py): environment variables, each declared
once (so101/runtime/settings.py says how) and read once when the node starts. Light: no simulator."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

from so101.bodies.scenario import SCENARIO_ENV_VAR, SCENARIO_HELP, ReadsScenario, Scenario, parse_scenario
from so101.bodies.settings import read_language, read_lockstep_fps
from so101.lang import DEFAULT_LANGUAGE, ENV_VAR as LANG_ENV_VAR
from so101.observe import ALL_OBSERVED, OBSERVE_ENV_VAR, Observed, parse_observed
from so101.runtime.settings import (
    EnvironSettings, Setting, parse_number, read_choice, read_image_size, read_number, read_optional_path,
    read_parsed, read_stripped_text, read_switch, read_text, read_whole_number, setting,
)
from so101.tasks import task_for_setting
from so101.tasks.episodes import DEFAULT_TIME_LIMIT_S

KEEP_CHOICES = ("success", "all")


def read_task(environ: Mapping[str, str], declared_setting: Setting) -> str:
    """A task's name (empty: none), refused in one line where no task has it."""
    name = read_stripped_text(environ, declared_setting)
    task_for_setting(name, declared_setting.env_var)
    return name


def read_required_task(environ: Mapping[str, str], declared_setting: Setting) -> str:
    name = read_task(environ, declared_setting)
    if not name:
        raise ValueError(f"{declared_setting.env_var} is empty: name the task (cube_to_box)")
    return name


def read_positive_number(environ: Mapping[str, str], declared_setting: Setting) -> float:
    value = parse_number(declared_setting.env_var, declared_setting.raw(environ), 0.0)
    if value <= 0:
        raise ValueError(f"{declared_setting.env_var}={value:g} is not a number of seconds above 0")
    return value


def read_fraction(environ: Mapping[str, str], declared_setting: Setting) -> float:
    value = parse_number(declared_setting.env_var, declared_setting.raw(environ), 0.0)
    if value > 1:
        raise ValueError(f"{declared_setting.env_var}={value:g} is not a share from 0 to 1")
    return value


@dataclass(frozen=True)
class ExpertSettings(EnvironSettings):
    """The scripted expert's (nodes/expert.py)."""

    task: str = setting("SO101_TASK", "cube_to_box", "the task the expert performs", read_required_task)
    noise: float = setting(
        "SO101_EXPERT_NOISE", "0", "perturbations of the expert's path, as a multiple of its standard ones (0 = none)",
        read_number(0.0))
    misses: float = setting(
        "SO101_EXPERT_MISSES", "0", "the share of episodes whose first grasp is put 30-45 mm beside the cube on purpose, "
        "so that they show a recovery: 0 (none) to 1", read_fraction)
    lockstep_fps: int = setting(
        "SO101_LOCKSTEP_FPS", "25", "the body's lockstep frame rate: the expert's clock is frames / fps",
        read_lockstep_fps)
    lang: str = setting(LANG_ENV_VAR, DEFAULT_LANGUAGE, "log language, `zh` or `en`", read_language)
    learner: Path | None = setting(
        "SO101_EXPERT_LEARNER", "", "a trained state policy's folder (DAgger, `so101 demos --learner`): it drives each "
        "episode first, unwritten, and the expert takes over from where it left things; empty = none "
        "(the node then runs under the policy environment's Python)", read_optional_path)
    takeover_s: float = setting(
        "SO101_EXPERT_TAKEOVER_S", "12", "with a learner: the expert takes over at a moment drawn from the episode's "
        "seed, from 0 to this many simulated seconds", read_positive_number)
    learner_sees: bool = setting(
        "SO101_EXPERT_LEARNER_SEES", "0", "`1`: the learner reads `seen_state`, what a seeing recipe's eyes (the "
        "perception node) found, where the expert reads the simulator's `object_state`",
        read_switch)


@dataclass(frozen=True)
class EpisodeSettings(ReadsScenario, EnvironSettings):
    """The episodes' runner's (nodes/episodes.py): which layouts, how long, what is written."""

    task: str = setting("SO101_TASK", "cube_to_box", "the task whose episodes run", read_required_task)
    first_seed: int = setting("SO101_SEED", "0", "episode i is laid out from seed SO101_SEED + i", read_whole_number)
    episodes: int = setting("SO101_EPISODES", "1", "how many episodes", read_whole_number)
    lockstep_fps: int = setting("SO101_LOCKSTEP_FPS", "25", "the body's lockstep frame rate", read_lockstep_fps)
    time_limit_s: float = setting(
        "SO101_TIME_LIMIT_S", f"{DEFAULT_TIME_LIMIT_S:g}", "simulated seconds an episode may take before it counts as failed",
        read_positive_number)
    results_path: Path = setting(
        "SO101_EPISODES_OUT", "episodes.jsonl", "a file the runner appends one JSON line to per episode, then `done`",
        lambda environ, declared_setting: Path(read_text(environ, declared_setting) or declared_setting.default))
    record_dir: Path | None = setting(
        "SO101_RECORD_DIR", "", "a LeRobot dataset to write the episodes into; empty = none", read_optional_path)
    spool_dir: Path | None = setting(
        "SO101_SPOOL_DIR", "", "a folder to keep each written episode whole in, for `so101 demos --workers` to merge "
        "in seed order (instead of SO101_RECORD_DIR); empty = none", read_optional_path)
    idle: bool = setting(
        "SO101_IDLE", "0", "`1`: no driver, the runner answers every frame with home (`so101 eval --idle`)",
        read_switch)
    keep: str = setting("SO101_KEEP", "success", "which episodes are written: `success` or `all`", read_choice(KEEP_CHOICES))
    image_size: tuple[int, int] | None = setting(
        "SO101_LOCKSTEP_PICTURES", "", "WIDTHxHEIGHT of the front and wrist pictures written; empty = no video",
        read_image_size)
    video_dir: Path | None = setting(
        "SO101_VIDEO_DIR", "", "a folder for each episode's front picture as an mp4; empty = none", read_optional_path)
    scenario: Scenario = setting(SCENARIO_ENV_VAR, "", SCENARIO_HELP, read_parsed(parse_scenario))
    environment_seen: bool = setting(
        "SO101_ENVIRONMENT_SEEN", "0", "`1`: the environment state written is `seen_state`, what a seeing recipe's eyes "
        "found (DAgger behind the eyes), rather than the simulator's `object_state`",
        read_switch)
    observed: Observed = setting(
        OBSERVE_ENV_VAR, str(ALL_OBSERVED), "what the written frames show, from state,environment,front,wrist "
        "(so101.observe): state,front,wrist leaves the objects' exact poses out", read_parsed(parse_observed))
    lang: str = setting(LANG_ENV_VAR, DEFAULT_LANGUAGE, "log language, `zh` or `en`", read_language)
