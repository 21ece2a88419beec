"""Reading `task_cmd` messages and the seeds they name: plain functions, no dora, no simulator.

A `task_cmd` asks the body running a task to lay its scene out again: `reset` (the next seed) or
`reset SEED`. The prompt, the episodes' runner and the body (so101/bodies/node_loop.py) share these.
"""

from __future__ import annotations

RESET_WORD = "reset"


def parse_seed(text: str) -> int:
    """A seed as typed (`--seed 7`, `reset 7`): a whole number >= 0; ValueError in one line otherwise."""
    try:
        seed = int(text.strip())
    except (ValueError, AttributeError):
        raise ValueError(f"a seed is a whole number >= 0, got {text!r}") from None
    if seed < 0:
        raise ValueError(f"a seed is a whole number >= 0, got {text!r}")
    return seed


def parse_reset(text: str) -> int | None:
    """A `task_cmd` (the prompt's `reset [SEED]`): the seed asked for, or None for the next one;
    ValueError in one line for anything else."""
    words = text.split()
    if not words or words[0] != RESET_WORD or len(words) > 2:
        raise ValueError(f"expected `{RESET_WORD}` or `{RESET_WORD} SEED`, got {text!r}")
    return parse_seed(words[1]) if len(words) == 2 else None
