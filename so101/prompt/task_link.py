"""The prompt's line to a body running a task: `reset` out on `task_cmd`, the body's answer back on
`task_status` (matched by a request number in the metadata), the latest `object_state` kept for `task`,
and news when the cube comes to rest in the box or is taken from there (so101.tasks.news: not at each
flicker of the success function). The body sends task_status when success changes and once a second,
so a cube taken away is news within a second."""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any, Callable

from so101.prompt.requests import Requests
from so101.tasks.news import BoxNews

# The body answers at its next event (a 4 ms tick); this allows for a loaded machine.
REPLY_WAIT_S = 3.0


@dataclass(frozen=True)
class TaskStatus:
    task: str
    seed: int
    success: bool


class TaskLink:
    """`send(task_cmd text, request id)` sends on `task_cmd`; `on_news(status, news)` is called (on the pump
    thread) with so101.tasks.news' LANDED or LEFT: the news to show."""

    def __init__(self, send: Callable[[str, str], None], on_news: Callable[[TaskStatus, str], None]):
        self._requests: Requests[TaskStatus] = Requests(send)
        self.on_news = on_news
        self._news = BoxNews()
        self._changed = threading.Condition()
        self.status: TaskStatus | None = None  # the latest task_status
        self._objects: Any = None  # the latest object_state, the Arrow array as it came

    def reset(self, seed: int | None) -> TaskStatus | None:
        """Lay the scene out again from `seed` (None: the next one): the body's answer, or None if none
        came within REPLY_WAIT_S."""
        return self._requests.ask("reset" if seed is None else f"reset {seed}", REPLY_WAIT_S)

    def on_status(self, success: bool, metadata: dict) -> None:
        """A `task_status` message (from the pump thread): an answer to a reset, or news."""
        status = TaskStatus(str(metadata.get("task", "")), int(metadata.get("seed", 0)), bool(success))
        reply_to = str(metadata.get("reply_to", ""))
        with self._changed:
            previous, self.status = self.status, status
            self._changed.notify_all()
        objects = self.object_state
        if reply_to or previous is None or (previous.task, previous.seed) != (status.task, status.seed):
            # A scene laid out again, or a prompt that just joined: what came before is no news.
            self._news.forget()
            if objects is not None:
                self._news.update(status.success, objects)
        elif objects is not None and (news := self._news.update(status.success, objects)) is not None:
            self.on_news(status, news)
        if reply_to:
            self._requests.answered(reply_to, status)

    def wait_for_status(self, timeout_s: float) -> TaskStatus | None:
        """The latest task_status, once one came (the body sends one a second) or `timeout_s` passed."""
        with self._changed:
            self._changed.wait_for(lambda: self.status is not None, timeout_s)
            return self.status

    def on_objects(self, values: Any) -> None:
        """The latest `object_state` (from the pump thread, at the body's rate): kept as it came."""
        self._objects = values

    @property
    def object_state(self) -> tuple[float, ...] | None:
        values = self._objects
        if values is None:
            return None
        return tuple(float(value) for value in values.to_pylist())
