"""Options shared by the subcommands: one error line that says what was wrong and what is accepted."""

from __future__ import annotations

import argparse
import os
from typing import Callable, TypeVar

from so101 import lang
from so101.observe import parse_observed

Parsed = TypeVar("Parsed")


def number(accepted: Callable[[float], bool], expected: str) -> Callable[[str], float]:
    """An argparse `type` for a number that `accepted` allows (NaN never is); otherwise
    "'TEXT' is not EXPECTED" ("a duration: use seconds, more than 0")."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = float("nan")
        if value != value or not accepted(value):
            raise argparse.ArgumentTypeError(f"{text!r} is not {expected}")
        return value

    return parse


def parsed_by(parse: Callable[[str], Parsed]) -> Callable[[str], Parsed]:
    """An argparse `type` made of a parser whose ValueError is one line for the user."""
    def parse_argument(text: str) -> Parsed:
        try:
            return parse(text)
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error)) from None
    return parse_argument


# A `type`, not `choices`: argparse passes a string default through `type` but never checks it
# against `choices`, so a bad $SO101_LANG would crash later. An empty one (unset) is the locale's.
_checked_language = parsed_by(lambda text: lang.session_language(text, os.environ))


def add_language_option(parser: argparse.ArgumentParser, what: str) -> None:
    """--lang zh|en, defaulting to $SO101_LANG, else the locale's (so101.lang.session_language); `what` says
    what it sets."""
    parser.add_argument(
        "--lang", type=_checked_language, metavar="{zh,en}", default=os.environ.get(lang.ENV_VAR, ""),
        help=f"language of {what} (default: ${lang.ENV_VAR}, else the locale's: zh for a Chinese, C or no "
        "locale, en for another)",
    )


def whole_number(lowest: int, highest: int) -> Callable[[str], int]:
    """An argparse `type` for a whole number from `lowest` to `highest`."""

    def parse(text: str) -> int:
        if not text.strip().isdigit() or not lowest <= int(text) <= highest:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number from {lowest} to {highest}")
        return int(text)

    return parse


def image_size(text: str) -> tuple[int, int]:
    """An argparse `type` for a picture size, "WIDTHxHEIGHT" (so101.runtime.settings.parse_image_size's rule)."""
    from so101.runtime.settings import parse_image_size

    try:
        size = parse_image_size(text)
    except ValueError:
        size = None
    if size is None:
        raise argparse.ArgumentTypeError(f"{text!r} is not WIDTHxHEIGHT in even pixels from 16 to 4096, e.g. 640x480")
    return size


def add_camera_size_option(parser: argparse.ArgumentParser, default: str | None, purpose: str,
                           default_text: str = "") -> None:
    """--camera-size WxH (and its older name --image-size): the cameras' picture size, as `image_size`
    (None by default where `default` is None: the command chooses, as `default_text` says)."""
    parser.add_argument("--camera-size", "--image-size", dest="image_size", type=image_size, default=default,
                        metavar="WxH", help=f"{purpose} (default {default_text or default}; 96x72 and up: small "
                                            "pictures train a policy that sees on a CPU)")

observed_list = parsed_by(parse_observed)  # --observe
