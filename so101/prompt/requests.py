"""Commands the prompt sends to another node with a request number, and the answers that come back
naming it in their `reply_to` (the recorder's `record_status`, a task's `task_status`)."""

from __future__ import annotations

import itertools
import threading
from typing import Callable, Generic, TypeVar

Answer = TypeVar("Answer")


class Requests(Generic[Answer]):
    """`send(text, request number)` sends a command; `answered` (from the pump thread) hands back the
    answer to one; `ask` sends and waits for it."""

    def __init__(self, send: Callable[[str, str], None]):
        self.send = send
        self._numbers = itertools.count(1)
        self._waiting: set[str] = set()  # requests whose `ask` still waits
        self._answers: dict[str, Answer] = {}
        self._answered = threading.Condition()

    def ask(self, text: str, timeout_s: float) -> Answer | None:
        """The answer to `text`; None if none came within `timeout_s`."""
        request = str(next(self._numbers))
        with self._answered:
            self._waiting.add(request)
        self.send(text, request)
        with self._answered:
            self._answered.wait_for(lambda: request in self._answers, timeout_s)
            self._waiting.discard(request)
            return self._answers.pop(request, None)

    def answered(self, reply_to: str, answer: Answer) -> bool:
        """Hands `answer` to the `ask` waiting for it; False if none waits (it gave up: the answer is late)."""
        with self._answered:
            if reply_to not in self._waiting:
                return False
            self._answers[reply_to] = answer
            self._answered.notify_all()
            return True
