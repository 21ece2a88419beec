"""The language a session prints in: zh (the course's) or en.

The rule, in one place (`session_language`): --lang, else $SO101_LANG, else the locale
(LC_ALL, else LC_MESSAGES, else LANG, as POSIX reads them): one naming Chinese (zh_CN.UTF-8,
zh_TW, ...) is zh, any other language is en, and none at all, C or POSIX (a bare container's)
is zh, the course's language. A `so101` command decides it once and hands it, as SO101_LANG,
to every node it starts, so every line of a session agrees. A node reads SO101_LANG alone
(`language_from_environ`; unset, zh): started by `dora run dataflow.yml`, it speaks what the
dataflow's `env:` says, as the prompt started by hand beside it does.
A value that is neither zh nor en is refused in one line.
"""

from __future__ import annotations

from typing import Mapping

LANGUAGES = ("zh", "en")
DEFAULT_LANGUAGE = "zh"
ENV_VAR = "SO101_LANG"
# The locale's variables, the first one set deciding (POSIX's order for messages).
LOCALE_VARS = ("LC_ALL", "LC_MESSAGES", "LANG")
# Locales that name no language: the course's language.
NEUTRAL_LOCALES = ("C", "POSIX")


def language(value: str | None) -> str:
    """`value` checked: zh or en, DEFAULT_LANGUAGE for None or an empty string; ValueError otherwise."""
    if not value:
        return DEFAULT_LANGUAGE
    if value not in LANGUAGES:
        raise ValueError(f"unknown language {value!r} (from --lang or ${ENV_VAR}); use zh or en")
    return value


def language_from_environ(environ: Mapping[str, str]) -> str:
    """A node's language: SO101_LANG's, zh when unset; ValueError, in one line, for a value that is neither zh nor en."""
    return language(environ.get(ENV_VAR))


def locale_language(environ: Mapping[str, str]) -> str:
    """The language the locale names: zh for a Chinese one, none, C or POSIX; en for any other."""
    locale = next((environ[name] for name in LOCALE_VARS if environ.get(name)), "")
    name = locale.split(".")[0].split("@")[0]
    if not name or name in NEUTRAL_LOCALES or name.lower().startswith("zh"):
        return DEFAULT_LANGUAGE
    return "en"


def session_language(chosen: str | None, environ: Mapping[str, str]) -> str:
    """The language of a session a person starts: `chosen` (--lang) if given, else $SO101_LANG, else
    the locale's (locale_language). ValueError, in one line, for a --lang or $SO101_LANG that is neither zh nor en."""
    if chosen:
        return language(chosen)
    if environ.get(ENV_VAR):
        return language(environ[ENV_VAR])
    return locale_language(environ)
