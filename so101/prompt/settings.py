"""The prompt's settings: five environment variables, read once when the node starts.

Each field of `PromptSettings` declares its variable, its default and what it means, in one
place: `from_environ` reads them, `environment_help` lists them for `--help`. An unset or
empty variable means its default.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Callable, Mapping

from so101.lang import DEFAULT_LANGUAGE, LANGUAGES, language
from so101.runtime.dataflow import ROOT


def _language(value: str) -> str:
    try:
        return language(value)
    except ValueError:
        # The prompt takes no --lang, so so101.lang's wording (which names it) would mislead.
        raise ValueError(f"is not one of: {', '.join(LANGUAGES)}") from None


def _path(value: str) -> Path:
    return Path(value).expanduser()


def _port(value: str) -> int | None:
    value = value.strip()
    if not value:
        return None
    if not (value.isdigit() and 0 < int(value) < 65536):
        raise ValueError("is not a port number (1-65535)")
    return int(value)


def _setting(variable: str, default: str, meaning: str, read: Callable[[str], object]):
    """A field read from `variable` by `read` (which raises ValueError, in words that follow
    "NAME='value'", for a value it refuses); `read(default)` when the variable is unset or empty."""
    return field(metadata={"variable": variable, "default": default, "meaning": meaning, "read": read})


@dataclass(frozen=True)
class PromptSettings:
    """What the prompt reads from its environment; each field names its variable."""

    lang: str = _setting("SO101_LANG", DEFAULT_LANGUAGE, "reply language, zh (the course's) or en", _language)
    poses_file: Path = _setting("SO101_POSES_FILE", str(ROOT / "saved_poses.json"), "where `save` keeps poses", _path)
    history_file: Path = _setting("SO101_HISTORY_FILE", "~/.so101_history", "the prompt's line history", _path)
    log_file: Path = _setting(
        "SO101_PROMPT_LOG", str(ROOT / "out" / "keyboard_control.log"), "where dora's own log lines go", _path
    )
    daemon_port: int | None = _setting(
        "SO101_DAEMON_PORT", "", "the --local-listen-port of the dora daemon to join through (on a cluster, "
        "this machine's); unset: dora's own, 53291", _port,
    )

    @classmethod
    def from_environ(cls, environ: Mapping[str, str]) -> PromptSettings:
        """The settings `environ` gives; ValueError, in one line, naming the first bad value."""
        values = {}
        for setting in fields(cls):
            variable, read = setting.metadata["variable"], setting.metadata["read"]
            raw = environ.get(variable) or setting.metadata["default"]
            try:
                values[setting.name] = read(raw)
            except ValueError as error:
                raise ValueError(f"{variable}={raw!r} {error}") from None
        return cls(**values)


def environment_help() -> str:
    """The settings, a line each, for --help."""
    lines = ["environment:"]
    for setting in fields(PromptSettings):
        variable, default, meaning = (setting.metadata[key] for key in ("variable", "default", "meaning"))
        lines.append(f"  {variable:<19} {meaning}" + (f" (default {default})" if default else ""))
    return "\n".join(lines)
