"""A dora node's event loop, as every node here runs it: its inputs until STOP or Ctrl-C, then its close.

    with inputs_until_stop(node, close=view.close) as inputs:
        for event in inputs:  # INPUT events only
            if event["id"] == "tick":
                ...

dora ends a node with STOP; run by hand, a node ends at Ctrl-C the same way, with no traceback.
Other events (INPUT_CLOSED, ERROR, ...) carry nothing the nodes act on and are skipped; an input
id a node does not know falls through its if/elif. `close` runs however the loop ends: STOP,
Ctrl-C, a `return` inside the block, or an exception, which goes on up once it has run.
"""

from __future__ import annotations

import contextlib
import sys
from typing import Any, Callable, Iterable, Iterator

# A dora event: {"type": "INPUT", "id": ..., "value": ..., "metadata": {...}}, or STOP, ...
Event = dict[str, Any]
# A joint_cmd whose metadata has this key is one of a stream (the leader node's, a tick each): not logged.
STREAM_KEY = "stream"


def cannot_start(error: Exception, node_id: str = "simulation") -> int:
    """One line on stderr and the exit code for a setting or a model that is wrong."""
    print(f"[{node_id}] cannot start: {error}", file=sys.stderr, flush=True)
    return 2


def inputs(events: Iterable[Event]) -> Iterator[Event]:
    """The INPUT events of `events` (a dora Node, or any iterable of its events) until STOP."""
    for event in events:
        if event["type"] == "STOP":
            return
        if event["type"] == "INPUT":
            yield event


@contextlib.contextmanager
def inputs_until_stop(events: Iterable[Event], close: Callable[[], None]) -> Iterator[Iterator[Event]]:
    """The block's inputs (see `inputs`); Ctrl-C ends the block like STOP, and `close` runs at its end."""
    try:
        yield inputs(events)
    except KeyboardInterrupt:
        pass  # Ctrl-C on a node run by hand: stop as at STOP
    finally:
        close()


def until_closed(events: Iterable[Event], input_id: str) -> Iterator[Event]:
    """`events` until the input `input_id` closes (its sender ended), as if STOP had come then."""
    for event in events:
        if event["type"] == "INPUT_CLOSED" and event.get("id") == input_id:
            return
        yield event
