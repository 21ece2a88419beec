"""The language a session prints in: zh (the course's) or en, from --lang or SO101_LANG.

One rule everywhere: unset or empty means zh; anything but zh or en is refused in one line.
"""

from __future__ import annotations

from typing import Mapping

LANGUAGES = ("zh", "en")
DEFAULT_LANGUAGE = "zh"
ENV_VAR = "SO101_LANG"


def language(value: str | None) -> str:
    """`value` checked: zh or en, DEFAULT_LANGUAGE for None or an empty string; ValueError otherwise."""
    if not value:
        return DEFAULT_LANGUAGE
    if value not in LANGUAGES:
        raise ValueError(f"unknown language {value!r} (from --lang or ${ENV_VAR}); use zh or en")
    return value


def language_from_environ(environ: Mapping[str, str]) -> str:
    """SO101_LANG's language; ValueError, in one line, for a value that is neither zh nor en."""
    return language(environ.get(ENV_VAR))
