"""The web view node's settings (nodes/web_view.py), declared as so101/runtime/settings.py says."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

from so101.assets import ASSETS_ENV_VAR
from so101.bodies.scenario import SCENARIO_ENV_VAR, SCENARIO_HELP, ReadsScenario, Scenario, parse_scenario
from so101.tasks.settings import read_task
from so101.runtime.settings import (
    EnvironSettings, Setting, read_optional_path, read_parsed, read_stripped_text, setting,
)

DEFAULT_HOST = "127.0.0.1"  # this machine only: anyone who can reach the port sees the arm
DEFAULT_PORT = 8101
# Hosts that serve on every address of the machine.
EVERY_ADDRESS = ("0.0.0.0", "::", "")
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")


def page_address(host: str, port: int) -> str:
    """The address to open: served on every address, this machine's own is one that works."""
    shown = "127.0.0.1" if host in EVERY_ADDRESS else f"[{host}]" if ":" in host else host
    return f"http://{shown}:{port}/"


def read_port(environ: Mapping[str, str], declared_setting: Setting) -> int:
    text = declared_setting.raw(environ).strip()
    if not text.isdigit() or not 1 <= int(text) <= 65535:
        raise ValueError(f"{declared_setting.env_var}={text!r}: expected a TCP port, a whole number from 1 to 65535")
    return int(text)


@dataclass(frozen=True)
class WebViewSettings(ReadsScenario, EnvironSettings):
    host: str = setting("SO101_WEB_HOST", DEFAULT_HOST,
                        "the address the page is served on; 127.0.0.1 = this machine only", read_stripped_text)
    port: int = setting("SO101_WEB_PORT", str(DEFAULT_PORT), "the page's TCP port", read_port)
    task: str = setting("SO101_TASK", "", "the task whose objects the page draws, posed by `object_state`; empty = none",
                        read_task)
    scenario: Scenario = setting(SCENARIO_ENV_VAR, "", SCENARIO_HELP + "; the page draws each layout in its looks and "
                                 "its cube at its physics' size", read_parsed(parse_scenario))
    assets_dir: Path | None = setting(
        ASSETS_ENV_VAR, "", "where the model is; empty = where `so101 assets` puts it", read_optional_path)
