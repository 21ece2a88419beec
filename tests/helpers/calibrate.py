"""`so101 calibrate` as a person runs it, its output read as it comes and lines typed on its stdin."""

from __future__ import annotations

import select
import subprocess
import time

from tests.helpers.dataflow import SO101, dora_env


class Calibrate:
    """`so101 calibrate` as a person runs it: its output read as it comes, lines typed on its stdin."""

    def __init__(self, *args: str, lang: str = "en"):
        self.process = subprocess.Popen([str(SO101), "calibrate", *args], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        stderr=subprocess.PIPE, env=dora_env(SO101_LANG=lang))
        self.output = b""

    def wait_for(self, text: str, timeout_s: float = 20) -> None:
        deadline = time.monotonic() + timeout_s
        while text.encode() not in self.output:
            assert time.monotonic() < deadline and self.process.poll() is None, self.output.decode()
            if select.select([self.process.stdout], [], [], 0.1)[0]:
                self.output += self.process.stdout.read1(4096)

    def enter(self) -> None:
        self.process.stdin.write(b"\n")
        self.process.stdin.flush()

    def end_input(self) -> None:
        """Ctrl-D: the end of the input."""
        self.process.stdin.close()
        self.process.stdin = None  # communicate() must not flush it again

    def finish(self) -> tuple[int, str, str]:
        out, err = self.process.communicate(timeout=30)
        return self.process.returncode, (self.output + out).decode(), err.decode()
