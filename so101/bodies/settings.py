"""The body nodes' settings: environment variables, each declared once, as a field of a frozen
dataclass (so101/runtime/settings.py says how). The docs' tables of the body nodes are made from
these declarations (docs/hooks.py; tests/test_settings.py).
`NodeSettings` is what the shared loop reads for every body; each body adds its own
(so101.bodies.registry names which). A bad value is a ValueError in one line, which the
node prints and exits 2 on (so101.runtime.node_events.cannot_start).

Light on purpose: no physics engine and no serial port is imported here.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Self

from so101.assets import ASSETS_ENV_VAR
from so101.bodies.pd_servo import DEFAULT_DAMPING_RATIO
from so101.bodies.scenario import SCENARIO_ENV_VAR, SCENARIO_HELP, ReadsScenario, Scenario, parse_scenario
from so101.feetech.calibration import parse_joint_signs
from so101.runtime.display import MODE_ENV_VAR
from so101.lang import DEFAULT_LANGUAGE, ENV_VAR as LANG_ENV_VAR, language_from_environ
from so101.runtime.settings import (
    EnvironSettings, Setting, parse_number, read_choice, read_image_size, read_number, read_optional_number, read_optional_path,
    read_file_path, read_parsed, read_stripped_text, read_text, read_whole_number, setting,
)
from so101.runtime.lockstep import steps_per_frame
from so101.runtime.versions import spawning_daemon_version_problem

# "position": the course's POSITION_CONTROL motor. "servo": a PD torque servo, in
# which the damping ratio decides whether a step overshoots (exercise 2).
CONTROL_MODES = ("position", "servo")

DEFAULT_MAX_SPEED_DEG_S = 90.0
DEFAULT_BUS_RETRIES = 5
CALIBRATE_HINT = "make one with `so101 calibrate --port {port} --out FILE`, or use LeRobot's so101_follower calibration"


def read_language(environ: Mapping[str, str], declared_setting: Setting) -> str:
    # The project's one rule for SO101_LANG (so101.lang); the field's env_var is its LANG_ENV_VAR.
    return language_from_environ(environ)


def check_control_mode(control_mode: str) -> str:
    """`control_mode` if it is one of CONTROL_MODES; ValueError in one line otherwise."""
    if control_mode not in CONTROL_MODES:
        raise ValueError(f"unknown control mode {control_mode!r}; use one of: {', '.join(CONTROL_MODES)}")
    return control_mode


def read_control_mode(environ: Mapping[str, str], declared_setting: Setting) -> str:
    return check_control_mode(declared_setting.raw(environ))


def read_lockstep_fps(environ: Mapping[str, str], declared_setting: Setting) -> int:
    fps = read_whole_number(environ, declared_setting)
    if fps:
        try:
            steps_per_frame(fps)
        except ValueError as error:
            raise ValueError(f"{declared_setting.env_var}: {error}") from None
    return fps


def read_joint_signs(environ: Mapping[str, str], declared_setting: Setting) -> tuple[int, ...]:
    return parse_joint_signs(declared_setting.raw(environ))


def read_torque_percent(environ: Mapping[str, str], declared_setting: Setting) -> float:
    torque = parse_number(declared_setting.env_var, declared_setting.raw(environ), 1.0)
    if torque > 100:
        raise ValueError(f"{declared_setting.env_var}={torque:g} is above 100 (a percentage of the servo's maximum)")
    return torque


# -- the settings ------------------------------------------------------------------------------


@dataclass(frozen=True)
class NodeSettings(ReadsScenario, EnvironSettings):
    """What the shared loop reads for every body (the body's own settings apart)."""

    display_mode: str = setting(
        MODE_ENV_VAR, "auto",
        "`gui` (window), `direct` (headless) or `auto` (a window where a display is reachable, else headless with a "
        "one-line notice)", read_text)
    image_hz: float = setting("SO101_IMAGE_HZ", "0", "rate of the `image` output; 0 = off", read_number(0.0))
    fast_steps: int = setting(
        "SO101_FAST_STEPS", "0", "N > 0: fast mode (no wall-clock pacing, N steps per published state; see the benchmark)",
        read_whole_number)
    tick_log_path: str = setting(
        "SO101_TICK_LOG", "", "a file for per-tick timings and step counts; in lockstep, each frame's round trip to "
        "its joint_cmd and its episode (used by `so101 bench`)", read_text)
    lang: str = setting(LANG_ENV_VAR, DEFAULT_LANGUAGE, "log language, `zh` or `en`", read_language)
    task: str = setting(
        "SO101_TASK", "", "a task's scene on the floor (`cube_to_box`; simulations only); empty = the arm alone",
        read_stripped_text)  # the node checks the name (so101.tasks.task_for_setting): tasks sit above bodies
    seed: int = setting("SO101_SEED", "0", "the task's first layout (a whole number)", read_whole_number)
    lockstep_fps: int = setting(
        "SO101_LOCKSTEP_FPS", "0",
        "N > 0: lockstep (no timer): each `joint_cmd` steps 1/N s of simulated time, then the next frame goes out "
        "(`so101 demos`, `so101 eval`; N a divisor of 250)", read_lockstep_fps)
    lockstep_pictures: tuple[int, int] | None = setting(
        "SO101_LOCKSTEP_PICTURES", "",
        "WIDTHxHEIGHT: in lockstep, each frame carries the task's front and wrist pictures on `image` and "
        "`wrist_image`, drawn for that frame; empty = none", read_image_size)
    scenario: Scenario = setting(SCENARIO_ENV_VAR, "", SCENARIO_HELP, read_parsed(parse_scenario))
    lockstep_episode_frames: int = setting(
        "SO101_EPISODE_FRAMES", "0",
        "N > 0: in lockstep, an episode's last frame is at most N; after it, or after a frame whose `task_status` "
        "says success, the body holds still until the next reset, so the runner that ends episodes can watch "
        "beside the loop; 0 = no end", read_whole_number)

    @classmethod
    def from_environ(cls, environ: Mapping[str, str]) -> Self:
        """Also refuses, in one line, a dora daemon that started the node and runs another dora
        version than the node's library."""
        problem = spawning_daemon_version_problem()
        if problem:
            raise ValueError(problem)
        return super().from_environ(environ)


@dataclass(frozen=True)
class ModelSettings(EnvironSettings):
    """What a simulated body loads: the model files."""

    assets_dir: Path | None = setting(
        ASSETS_ENV_VAR, "", "where the model is; empty = where `so101 assets` puts it (the checkout's `assets/SO101`)",
        read_optional_path)


@dataclass(frozen=True)
class PyBulletSettings(ModelSettings):
    """The PyBullet body's own settings (nodes/simulation_node.py)."""

    control_mode: str = setting(
        "SO101_CONTROL", "position",
        "`position`: the course's `POSITION_CONTROL`; `servo`: a PD torque servo for exercise 2", read_control_mode)
    servo_damping_ratio: float = setting(
        "SO101_SERVO_ZETA", f"{DEFAULT_DAMPING_RATIO:g}", "the servo's damping ratio ζ (servo mode only)", read_number(0.0))


@dataclass(frozen=True)
class MuJoCoSettings(ModelSettings):
    """The MuJoCo body's own settings (nodes/simulation_mujoco.py)."""

    joint_damping_n_m_s: float | None = setting(
        "SO101_MUJOCO_DAMPING", "", "every joint's damping in N·m·s/rad; empty = the MJCF's 0.60", read_optional_number(0.0))


@dataclass(frozen=True)
class ArmSettings(EnvironSettings):
    """The real arm's own settings (nodes/arm_node.py, dataflow_real.yml's `env:`)."""

    port: str = setting(
        "SO101_PORT", "", "the arm's serial port (`so101 fake-arm` prints an emulated one)", read_stripped_text,
        required="(the dataflow's env:, or so101 teleop --port) to the arm's serial port "
                 "(/dev/ttyACM0, ...; `so101 fake-arm` prints an emulated one)")
    calibration_file: Path = setting(
        "SO101_CALIBRATION", "", "LeRobot's so101_follower calibration JSON, or one from `so101 calibrate`", read_file_path,
        required="(the dataflow's env:, or so101 teleop --calibration) to the arm's calibration file; "
                 + CALIBRATE_HINT)
    max_speed_deg_s: float = setting(
        "SO101_MAX_SPEED_DEG_S", f"{DEFAULT_MAX_SPEED_DEG_S:g}", "how fast a goal may move, °/s", read_number(1.0))
    joint_signs: tuple[int, ...] = setting(
        "SO101_JOINT_SIGNS", "1,1,1,1,1,1", "`-1` flips a joint whose direction differs from the URDF's",
        read_joint_signs)
    torque_limit_percent: float = setting(
        "SO101_TORQUE_LIMIT", "100", "% of the servos' maximum torque (the Torque_Limit register)", read_torque_percent)
    retries: int = setting(
        "SO101_BUS_RETRIES", f"{DEFAULT_BUS_RETRIES}", "ticks a servo may fail to answer before the node stops",
        read_whole_number)
