"""Facts read from the dataflow description, as plain functions."""

from __future__ import annotations

import re

_TIMER = re.compile(r"^dora/timer/(millis|secs)/(\d+(?:\.\d+)?)$")


def timer_period_s(node_config: dict, input_id: str = "tick") -> float | None:
    """The period of a `dora/timer/...` input in seconds, or None if that input is not a timer.

    `node_config` is what `Node.node_config()` returns: {"inputs": {id: source-or-mapping}, ...}.
    """
    spec = (node_config or {}).get("inputs", {}).get(input_id)
    source = spec.get("source") if isinstance(spec, dict) else spec
    match = _TIMER.match(source or "") if isinstance(source, str) else None
    if not match:
        return None
    unit, amount = match.groups()
    return float(amount) / (1000.0 if unit == "millis" else 1.0)
