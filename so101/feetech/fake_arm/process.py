"""The emulated bus in a process of its own: what the tests use, so that nothing a test does
(holding the GIL, encoding video, starting a browser) starves the servos' replies, as nothing in a
driver's process can starve a real arm's.

    with FakeArmProcess() as arm:          # the same methods as FakeArm, each a message over a pipe
        calibration = calibrate_as_at_the_factory(arm)
        SO101Real(arm.port, calibration)   # the driver talks to it over its pseudo-terminal

Arguments and results cross the pipe pickled: a hand script given to `play_hand` must be a function
defined at a module's top level (or a functools.partial of one, or a bound method of a Keyframes).
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from multiprocessing.connection import Connection
from typing import Any, Callable, Sequence

from so101.feetech.fake_arm.arm import FakeArm
from so101.feetech.fake_arm.mechanics import ALL_IDS
from so101.feetech.fake_arm.servo import DEFAULT_SPEED_STEPS_S, Response

START_TIMEOUT_S = 30.0  # a fresh interpreter imports the emulator: well under a second on an idle machine
CLOSE_TIMEOUT_S = 5.0

# What a test may ask of the arm in the other process: FakeArm's public methods and attributes.
FORWARDED = frozenset(
    name for name in dir(FakeArm) if not name.startswith("_") and name not in ("start", "close", "on_calibration")
) | {"speed_steps_s", "calibrations_begun"}


def scaled_clock(time_scale: float) -> Callable[[], float]:
    """A clock that runs `time_scale` times as fast as time.monotonic(), from now: the emulator's
    motors and hands move that much faster than the wall clock."""
    start = time.monotonic()
    return lambda: start + (time.monotonic() - start) * time_scale


# Servos are hardware of their own: nothing the host runs delays their replies. The emulator stands in
# for them at EMULATOR_NICE where it may (as root), so that a loaded machine starves the drivers under
# test (as it would a real arm's) more than the servos. (What had starved them under load was the
# drivers spinning on the port, fixed in so101/feetech/bus.py; SCHED_FIFO, tried before that was found,
# left the emulated arm silent for over 200 ms in parallel suites.)
EMULATOR_NICE = -10


def raise_priority() -> None:
    """This thread (and the threads it starts later) at EMULATOR_NICE, if the system lets it; as it
    was otherwise."""
    try:
        os.setpriority(os.PRIO_PROCESS, 0, EMULATOR_NICE)
    except OSError:
        pass


def _serve(requests: Connection, connection: Connection) -> None:
    """The child: one FakeArm, started; every request answered until "close" or the parent is gone."""
    try:
        options, time_scale, search_path = requests.recv()
        sys.path[:] = search_path  # a hand script from a test module unpickles as it was pickled
        arm = FakeArm(**options, clock=scaled_clock(time_scale)).start()
    except Exception as error:  # a bad option: the parent raises it
        connection.send(("error", error))
        return
    connection.send(("ok", (arm.port, arm.ids)))
    try:
        while True:
            try:
                kind, name, args, kwargs = requests.recv()
            except (EOFError, OSError):  # the test process is gone: so is its arm
                return
            except Exception as error:  # arguments that do not unpickle here
                connection.send(("error", error))
                continue
            if kind == "close":
                connection.send(("ok", None))
                return
            try:
                value = getattr(arm, name)
                connection.send(("ok", value(*args, **kwargs) if kind == "call" else value))
            except Exception as error:
                connection.send(("error", error))
    finally:
        arm.close()


class FakeArmProcess:
    """A FakeArm served by a process of its own, with FakeArm's methods (forwarded over a pipe)."""

    def __init__(
        self,
        ids: Sequence[int] = ALL_IDS,
        speed_steps_s: float = DEFAULT_SPEED_STEPS_S,
        start_positions: dict[int, int] | None = None,
        time_scale: float = 1.0,
        response: Response = Response(),
    ):
        if not time_scale > 0:
            raise ValueError(f"time_scale must be positive, got {time_scale}")
        self._lock = threading.Lock()  # one request at a time on the pipes, whichever thread asks
        # A fresh interpreter (not a fork of the test process, which has threads), its stdin and stdout
        # the pipes of the requests and the answers; its stderr the test's.
        self._process = subprocess.Popen([sys.executable, "-c", f"from {__name__} import child_main; child_main()"],
                                         stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        assert self._process.stdin is not None and self._process.stdout is not None
        self._requests = Connection(os.dup(self._process.stdin.fileno()), readable=False)
        self._connection = Connection(os.dup(self._process.stdout.fileno()), writable=False)
        self._process.stdin.close()
        self._process.stdout.close()
        options = {"ids": tuple(ids), "speed_steps_s": speed_steps_s, "start_positions": start_positions,
                   "response": response}
        self._requests.send((options, time_scale, sys.path))
        if not self._connection.poll(START_TIMEOUT_S):
            self.close()
            raise RuntimeError(f"the emulated arm's process did not start within {START_TIMEOUT_S:g} s")
        try:
            self.port, self.ids = self._answer(self._connection.recv())
        except BaseException:
            self.close()
            raise

    def _answer(self, reply: tuple[str, Any]) -> Any:
        status, value = reply
        if status == "error":
            raise value
        return value

    def _request(self, kind: str, name: str, args: tuple[Any, ...] = (), kwargs: dict[str, Any] | None = None) -> Any:
        with self._lock:
            if self._process.poll() is not None:
                raise RuntimeError("the emulated arm's process has ended")
            self._requests.send((kind, name, args, kwargs or {}))
            return self._answer(self._connection.recv())

    def __getattr__(self, name: str) -> Any:
        if name not in FORWARDED:
            raise AttributeError(f"FakeArmProcess has no {name!r}")
        if callable(getattr(FakeArm, name, None)):
            return lambda *args, **kwargs: self._request("call", name, args, kwargs)
        return self._request("get", name)

    @property
    def packets_served(self) -> int:
        return self._request("get", "packets_served")

    @property
    def port_open(self) -> bool:
        return self._request("get", "port_open")

    @property
    def calibrations_begun(self) -> int:
        return self._request("get", "calibrations_begun")

    def close(self) -> None:
        """Stop the emulator and its process; safe to call twice."""
        with self._lock:
            if self._process.poll() is None:
                try:
                    self._requests.send(("close", "", (), {}))
                    if self._connection.poll(CLOSE_TIMEOUT_S):
                        self._connection.recv()
                    self._process.wait(CLOSE_TIMEOUT_S)
                except (OSError, EOFError, subprocess.TimeoutExpired):
                    self._process.kill()
                    self._process.wait()
            self._requests.close()
            self._connection.close()

    def __enter__(self) -> "FakeArmProcess":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def child_main() -> None:
    """The child process's entry: requests on stdin, answers on what was stdout (anything printed goes
    to stderr instead of into the pipe)."""
    answers_fd = os.dup(1)
    os.dup2(2, 1)
    raise_priority()
    _serve(Connection(0, writable=False), Connection(answers_fd, readable=False))
