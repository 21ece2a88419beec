"""The perception node's settings (nodes/perception.py), each declared once and read once at start."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from so101.lang import DEFAULT_LANGUAGE, ENV_VAR as LANG_ENV_VAR, language_from_environ
from so101.bodies.scenario import SCENARIO_ENV_VAR, ReadsScenario, Scenario, parse_scenario
from so101.runtime.settings import EnvironSettings, read_parsed, read_stripped_text, read_threads, setting
from so101.tasks.settings import read_task


@dataclass(frozen=True)
class PerceptionSettings(ReadsScenario, EnvironSettings):
    eyes_dir: Path = setting("SO101_EYES_DIR", "", "the eyes' folder (eyes.pt, eyes.json), as `so101 learn --sees` "
                             "writes it in its output's eyes/",
                             lambda environ, declared_setting: Path(read_stripped_text(environ, declared_setting)).expanduser(),
                             required="(so101 eval/teleop --policy DIR with a seeing recipe) to an eyes folder")
    task: str = setting("SO101_TASK", "cube_to_box", "the task whose objects the eyes find", read_task)
    scenario: Scenario = setting(SCENARIO_ENV_VAR, "", "where the front camera stands (the scenario's `camera_poses`: "
                                 "`--camera-pose front=FILE`), its geometry the eyes' instead of the one they learned "
                                 "with; empty = theirs", read_parsed(parse_scenario))
    threads: int = setting("SO101_EYES_THREADS", "1", "PyTorch's threads for the eyes on the CPU", read_threads)
    lang: str = setting(LANG_ENV_VAR, DEFAULT_LANGUAGE, "log language, `zh` or `en`",
                        lambda environ, declared_setting: language_from_environ(environ))
