"""The prompt's settings: five environment variables, each declared once (so101/runtime/settings.py
says how) and read once when the node starts. An unset or empty variable means its default.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

from so101.lang import DEFAULT_LANGUAGE, LANGUAGES, language
from so101.runtime.dataflow import ROOT
from so101.runtime.settings import EnvironSettings, Setting, declared, setting


def _raw_or_default(environ: Mapping[str, str], declared_setting: Setting) -> str:
    return environ.get(declared_setting.env_var) or declared_setting.default


def _refused(declared_setting: Setting, raw: str, accepted: str) -> ValueError:
    return ValueError(f"{declared_setting.env_var}={raw!r} {accepted}")


def read_language(environ: Mapping[str, str], declared_setting: Setting) -> str:
    raw = _raw_or_default(environ, declared_setting)
    try:
        return language(raw)
    except ValueError:
        # The prompt takes no --lang, so so101.lang's wording (which names it) would mislead.
        raise _refused(declared_setting, raw, f"is not one of: {', '.join(LANGUAGES)}") from None


def read_path(environ: Mapping[str, str], declared_setting: Setting) -> Path:
    return Path(_raw_or_default(environ, declared_setting)).expanduser()


def read_port(environ: Mapping[str, str], declared_setting: Setting) -> int | None:
    raw = _raw_or_default(environ, declared_setting)
    if not raw.strip():
        return None
    if not (raw.strip().isdigit() and 0 < int(raw) < 65536):
        raise _refused(declared_setting, raw, "is not a port number (1-65535)")
    return int(raw)


@dataclass(frozen=True)
class PromptSettings(EnvironSettings):
    """What the prompt reads from its environment."""

    lang: str = setting("SO101_LANG", DEFAULT_LANGUAGE, "reply language, zh (the course's) or en", read_language)
    poses_file: Path = setting("SO101_POSES_FILE", str(ROOT / "saved_poses.json"), "where `save` keeps poses", read_path)
    history_file: Path = setting("SO101_HISTORY_FILE", "~/.so101_history", "the prompt's line history", read_path)
    log_file: Path = setting(
        "SO101_PROMPT_LOG", str(ROOT / "out" / "keyboard_control.log"), "where dora's own log lines go", read_path,
    )
    daemon_port: int | None = setting(
        "SO101_DAEMON_PORT", "", "the --local-listen-port of the dora daemon to join through (on a cluster, "
        "this machine's); unset: dora's own, 53291", read_port,
    )


def environment_help() -> str:
    """The settings, a line each, for --help."""
    lines = ["environment:"]
    for each in declared(PromptSettings):
        lines.append(f"  {each.env_var:<19} {each.meaning}" + (f" (default {each.default})" if each.default else ""))
    return "\n".join(lines)
