"""The recorder's, the camera's and replay's settings: environment variables, each declared once
(so101/runtime/settings.py says how). `so101 teleop --record` and `so101 replay` set them."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from so101.assets import ASSETS_ENV_VAR
from so101.bodies.scenario import SCENARIO_ENV_VAR, SCENARIO_HELP, ReadsScenario, Scenario, parse_scenario
from so101.bodies.settings import read_language
from so101.tasks.settings import read_task
from so101.dataset.features import DEFAULT_FPS
from so101.lang import DEFAULT_LANGUAGE, ENV_VAR as LANG_ENV_VAR
from so101.dataset.recording import CAMERA_LOST_CHOICES
from so101.dataset.units import UNITS
from so101.observe import ALL_OBSERVED, OBSERVE_ENV_VAR, Observed, parse_observed
from so101.cameras.sources import parse_real_cameras
from so101.runtime.settings import (
    EnvironSettings, read_choice, read_file_path, read_fps, read_image_size, read_optional_path, read_parsed,
    read_whole_number, setting,
)

DEFAULT_IMAGE_SIZE = "320x240"


@dataclass(frozen=True)
class RecorderSettings(ReadsScenario, EnvironSettings):
    """nodes/recorder.py."""

    root: Path = setting(
        "SO101_RECORD_DIR", "", "the dataset's folder: made if missing, appended to if it is one", read_file_path,
        required="(so101 teleop --record DIR, or the dataflow's env:) to the dataset's folder")
    fps: int = setting("SO101_RECORD_FPS", str(DEFAULT_FPS), "frames per second", read_fps(1000))
    image_size: tuple[int, int] | None = setting(
        "SO101_RECORD_IMAGE_SIZE", DEFAULT_IMAGE_SIZE,
        "WIDTHxHEIGHT of the `image` input's pictures, stored as video; empty = no video (the `image` input unconnected)",
        read_image_size)
    lang: str = setting(LANG_ENV_VAR, DEFAULT_LANGUAGE, "reply language, `zh` or `en`", read_language)
    task: str = setting(
        "SO101_TASK", "", "the body's task: frames also hold its `object_state`, reward and success; empty = none",
        read_task)
    scenario: Scenario = setting(SCENARIO_ENV_VAR, "", SCENARIO_HELP, read_parsed(parse_scenario))
    observed: Observed = setting(
        OBSERVE_ENV_VAR, str(ALL_OBSERVED), "what the frames show, from state,environment,front,wrist (so101.observe), "
        "as far as the body has it: without a task no environment or wrist, without video no camera",
        read_parsed(parse_observed))
    real_cameras: tuple[str, ...] = setting(
        "SO101_RECORD_CAMERAS", "", "the real cameras recorded (`front`, `wrist`; nodes/real_camera.py): each picture "
        "is paired with the state of its capture, and one that stops ends the episode; empty = a simulation's camera",
        read_parsed(parse_real_cameras))
    camera_lost: str = setting(
        "SO101_RECORD_CAMERA_LOST", "save", "with real cameras, what becomes of the episode when one stops sending "
        "pictures: `save` it up to then, or `discard` it", read_choice(CAMERA_LOST_CHOICES))


@dataclass(frozen=True)
class CameraSettings(ReadsScenario, EnvironSettings):
    """nodes/camera.py."""

    image_size: tuple[int, int] | None = setting(
        "SO101_RECORD_IMAGE_SIZE", DEFAULT_IMAGE_SIZE, "WIDTHxHEIGHT of the pictures", read_image_size,
        required="to WIDTHxHEIGHT (e.g. 320x240)")
    assets_dir: Path | None = setting(
        ASSETS_ENV_VAR, "", "where the model is; empty = where `so101 assets` puts it", read_optional_path)
    task: str = setting("SO101_TASK", "", "the task whose objects the pictures show, posed by `object_state`; empty = none",
                        read_task)
    scenario: Scenario = setting(SCENARIO_ENV_VAR, "", SCENARIO_HELP, read_parsed(parse_scenario))


@dataclass(frozen=True)
class ReplaySettings(EnvironSettings):
    """nodes/replay.py."""

    root: Path = setting("SO101_REPLAY_DIR", "", "the dataset's folder", read_file_path,
                         required="(so101 replay DIR) to the dataset's folder")
    episode: int = setting("SO101_REPLAY_EPISODE", "0", "the episode to play", read_whole_number)
    units: str = setting("SO101_REPLAY_UNITS", "", "the dataset's joint units where its meta does not say: "
                         "degrees or normalized (empty: its meta's, or its values')", read_choice(("",) + UNITS))
    calibration: Path | None = setting("SO101_REPLAY_CALIBRATION", "", "the recording follower's LeRobot calibration "
                                       "JSON, for joints in normalized units (empty: the URDF's ranges)",
                                       read_optional_path)
    lang: str = setting(LANG_ENV_VAR, DEFAULT_LANGUAGE, "message language, `zh` or `en`", read_language)
