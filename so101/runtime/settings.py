"""A node's settings as a frozen dataclass whose every field is an environment variable,
declared once: its name, the value an unset variable has, one line of meaning, how it is read.

`from_environ` reads every field in declaration order; the docs' tables (docs/hooks.py) and `--help` are
made from, or held to, the same declarations (`declared`). A bad value is a ValueError in one
line that names the variable and what is accepted. The bodies' settings are in
so101/bodies/settings.py, the prompt's in so101/prompt/settings.py.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Callable, Mapping, Self

# The key of a field's Setting in its metadata.
SETTING = "so101.setting"


@dataclass(frozen=True)
class Setting:
    """One environment variable: its name, the value an unset one has, its meaning, and its reader."""

    env_var: str
    default: str
    meaning: str  # one line, as the docs' table of the node gives it
    # (environment, this setting) -> the value; ValueError in one line for a bad one.
    read: Callable[[Mapping[str, str], "Setting"], Any]
    # Where to set it, for a variable that may not be empty ("" = empty is allowed). It may
    # name the values of the fields declared before it, as {field_name}.
    required: str = ""

    def raw(self, environ: Mapping[str, str]) -> str:
        return environ.get(self.env_var, self.default)


def setting(env_var: str, default: str, meaning: str, read: Callable[[Mapping[str, str], Setting], Any],
            required: str = "") -> Any:
    """A dataclass field that is read from `env_var` (Any: the field's own annotation gives its type)."""
    return field(metadata={SETTING: Setting(env_var, default, meaning, read, required)})


def declared(settings_class: type[EnvironSettings]) -> tuple[Setting, ...]:
    """The settings a class declares, in field order."""
    return tuple(each.metadata[SETTING] for each in fields(settings_class))


@dataclass(frozen=True)
class EnvironSettings:
    """A frozen dataclass whose every field is a `setting(...)`."""

    @classmethod
    def from_environ(cls, environ: Mapping[str, str]) -> Self:
        """Every field from its variable, in declaration order; ValueError naming the first bad value
        and what is accepted."""
        values: dict[str, Any] = {}
        for each in fields(cls):
            declared_setting: Setting = each.metadata[SETTING]
            if declared_setting.required and not declared_setting.raw(environ).strip():
                where = declared_setting.required.format(**values)
                raise ValueError(f"{declared_setting.env_var} is empty: set it {where}")
            values[each.name] = declared_setting.read(environ, declared_setting)
        return cls(**values)


# -- readers: (environment, setting) -> the field's value --------------------------------------------------


def read_text(environ: Mapping[str, str], declared_setting: Setting) -> str:
    return declared_setting.raw(environ)


def read_stripped_text(environ: Mapping[str, str], declared_setting: Setting) -> str:
    return declared_setting.raw(environ).strip()


def read_file_path(environ: Mapping[str, str], declared_setting: Setting) -> Path:
    return Path(declared_setting.raw(environ).strip()).expanduser()


def read_optional_path(environ: Mapping[str, str], declared_setting: Setting) -> Path | None:
    raw = declared_setting.raw(environ).strip()
    return Path(raw).expanduser() if raw else None


def parse_number(env_var: str, raw: str, minimum: float) -> float:
    try:
        value = float(raw)
    except ValueError:
        value = float("nan")
    if not value >= minimum:  # also rejects NaN
        raise ValueError(f"{env_var}={raw!r} is not a number >= {minimum:g}")
    return value


def read_number(minimum: float) -> Callable[[Mapping[str, str], Setting], float]:
    def read(environ: Mapping[str, str], declared_setting: Setting) -> float:
        return parse_number(declared_setting.env_var, declared_setting.raw(environ), minimum)
    return read


def read_optional_number(minimum: float) -> Callable[[Mapping[str, str], Setting], float | None]:
    """A number, or None for an empty value."""
    def read(environ: Mapping[str, str], declared_setting: Setting) -> float | None:
        raw = declared_setting.raw(environ)
        return parse_number(declared_setting.env_var, raw, minimum) if raw.strip() else None
    return read


def read_whole_number(environ: Mapping[str, str], declared_setting: Setting) -> int:
    raw = declared_setting.raw(environ)
    if not raw.strip().isdigit():
        raise ValueError(f"{declared_setting.env_var}={raw!r} is not a whole number >= 0")
    return int(raw)


def read_fps(highest: int) -> Callable[[Mapping[str, str], Setting], int]:
    """A frame rate, a whole number from 1 to `highest` per second."""
    def read(environ: Mapping[str, str], declared_setting: Setting) -> int:
        fps = read_whole_number(environ, declared_setting)
        if not 1 <= fps <= highest:
            raise ValueError(f"{declared_setting.env_var}={fps} is not a frame rate from 1 to {highest} per second")
        return fps
    return read


def parse_image_size(text: str, env_var: str = "image size") -> tuple[int, int] | None:
    """"WIDTHxHEIGHT" -> (width, height); "" -> None (no pictures)."""
    raw = text.strip().lower()
    if not raw:
        return None
    width, _, height = raw.partition("x")
    if not (width.isdigit() and height.isdigit() and 16 <= int(width) <= 4096 and 16 <= int(height) <= 4096
            and int(width) % 2 == 0 and int(height) % 2 == 0):
        raise ValueError(f"{env_var}={text!r} is not WIDTHxHEIGHT in even pixels from 16 to 4096 (e.g. 320x240), "
                         "or empty for no video")
    return int(width), int(height)


def read_image_size(environ: Mapping[str, str], declared_setting: Setting) -> tuple[int, int] | None:
    return parse_image_size(declared_setting.raw(environ), declared_setting.env_var)


def read_choice(choices: tuple[str, ...]) -> Callable[[Mapping[str, str], Setting], str]:
    """One of `choices`, as written (spaces around it ignored)."""
    def read(environ: Mapping[str, str], declared_setting: Setting) -> str:
        raw = declared_setting.raw(environ).strip()
        if raw not in choices:
            raise ValueError(f"{declared_setting.env_var}={raw!r} is not one of: {', '.join(choices)}")
        return raw
    return read


def read_switch(environ: Mapping[str, str], declared_setting: Setting) -> bool:
    """`1` on, `0` off (read_choice's refusal for anything else)."""
    return read_choice(("0", "1"))(environ, declared_setting) == "1"


def read_parsed(parse: Callable[[str], Any]) -> Callable[[Mapping[str, str], Setting], Any]:
    """`parse(text)`, whose ValueError (one line) is named by the setting."""
    def read(environ: Mapping[str, str], declared_setting: Setting) -> Any:
        try:
            return parse(declared_setting.raw(environ))
        except ValueError as error:
            raise ValueError(f"{declared_setting.env_var}: {error}") from None
    return read


def read_threads(environ: Mapping[str, str], declared_setting: Setting) -> int:
    """PyTorch's threads for a node: a whole number from 1 to 256."""
    threads = read_whole_number(environ, declared_setting)
    if not 1 <= threads <= 256:
        raise ValueError(f"{declared_setting.env_var}={threads} is not a number of threads from 1 to 256")
    return threads
