"""Number options for the command line: one error line that says what was wrong and what is accepted."""

from __future__ import annotations

import argparse
from typing import Callable


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
