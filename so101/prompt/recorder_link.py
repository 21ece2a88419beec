"""The prompt's line to the recorder node: a command out on `record_cmd`, its answer back on
`record_status` (matched by a request number in the metadata), and the recorder's own news (an
episode saved in the background) shown as it comes."""

from __future__ import annotations

from typing import Callable

from so101.dataset.messages import encode_record_cmd
from so101.prompt.requests import Requests

# The recorder answers at its next event (a 5 ms tick); this allows for a loaded machine.
REPLY_WAIT_S = 3.0


class RecorderLink:
    """`send(record_cmd text, request id)` sends on `record_cmd`; `show(line)` prints news at once."""

    def __init__(self, send: Callable[[str, str], None], show: Callable[[str], None]):
        self._requests: Requests[list[str]] = Requests(send)
        self.show = show

    def ask(self, command: str, task: str = "", timeout_s: float = REPLY_WAIT_S) -> list[str] | None:
        """The recorder's answer to one command, as lines; None if it did not answer in time."""
        return self._requests.ask(encode_record_cmd(command, task), timeout_s)

    def on_status(self, text: str, reply_to: str) -> None:
        """A `record_status` message (from the pump thread): an answer, or news to show now. An answer
        that comes after the prompt said the recorder did not answer is shown as news: it is the truth."""
        lines = text.split("\n")
        if reply_to and self._requests.answered(reply_to, lines):
            return
        for line in lines:
            self.show(f"  {line}")
