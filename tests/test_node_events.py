"""The event loop every node shares (so101/runtime/node_events.py): inputs until STOP or Ctrl-C, then close."""

from __future__ import annotations

import pytest

from so101.runtime.node_events import inputs_until_stop


def tick(number: int) -> dict:
    return {"type": "INPUT", "id": "tick", "value": number, "metadata": {}}


STOP = {"type": "STOP"}


def test_the_inputs_come_until_stop_other_events_skipped_and_close_runs_once():
    closed = []
    events = [tick(1), {"type": "INPUT_CLOSED", "id": "joint_state"}, {"type": "ERROR", "error": "x"}, tick(2), STOP,
              tick(3)]
    with inputs_until_stop(events, close=lambda: closed.append(True)) as inputs:
        seen = [event["value"] for event in inputs]
    assert seen == [1, 2] and closed == [True]


def test_ctrl_c_ends_the_loop_like_stop_with_no_traceback():
    closed, seen = [], []
    with inputs_until_stop([tick(1), tick(2), tick(3)], close=lambda: closed.append(True)) as inputs:
        for event in inputs:
            seen.append(event["value"])
            if event["value"] == 2:
                raise KeyboardInterrupt
    assert seen == [1, 2] and closed == [True]


def test_a_return_or_an_error_inside_the_loop_still_closes():
    closed = []

    def first_tick() -> int:
        with inputs_until_stop([tick(7), tick(8)], close=lambda: closed.append("returned")) as inputs:
            for event in inputs:
                return event["value"]
        return 0

    assert first_tick() == 7
    with pytest.raises(ValueError, match="bad"):
        with inputs_until_stop([tick(1)], close=lambda: closed.append("raised")) as inputs:
            for _ in inputs:
                raise ValueError("bad")
    assert closed == ["returned", "raised"]
