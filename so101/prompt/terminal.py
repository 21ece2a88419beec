"""The prompt's terminal: dora's log lines kept out of it, line editing with a history, and
single key presses for jogging.

dora's Rust logging in a node writes JSON lines straight to file descriptor 1 (say, one
warning per input it had to drop while the machine was busy). Those lines must not land
between a person's commands. So, inside `dora_logs_to(path)`, descriptor 1 is the log
file, and Python's stdout is a copy of the terminal. Python's input() edits lines with
readline only when C's `stdout` stream is the same terminal as sys.stdout, so that stream
is moved to the copy too (glibc and macOS; elsewhere input() still works, without line
editing).
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import logging
import os
import sys
from pathlib import Path
from typing import Callable

from so101.runtime.logs import keep_last_bytes

log = logging.getLogger(__name__)

# Every session appends dora's log lines to the same file: each starts by cutting it to its last 256 KiB.
LOG_KEPT_BYTES = 256 * 1024

# The name of C's `stdout` variable: glibc, then macOS.
_C_STDOUT_NAMES = ("stdout", "__stdoutp")


def _c_stdout():
    """C's `stdout` variable as a ctypes pointer, or None where it cannot be found."""
    try:
        libc = ctypes.CDLL(None)
    except OSError:
        return None
    for name in _C_STDOUT_NAMES:
        try:
            return libc, ctypes.c_void_p.in_dll(libc, name)
        except ValueError:
            continue
    return None


def _writes_to_descriptor_1(stream) -> bool:
    try:
        return stream.fileno() == 1
    except (AttributeError, ValueError, io.UnsupportedOperation):
        return False


@contextlib.contextmanager
def dora_logs_to(log_path: Path, restore: bool = True):
    """Descriptor 1 goes to `log_path` (appended, once cut to its last LOG_KEPT_BYTES) inside the
    block; Python's prints and the line editor go to the terminal as before. With restore=False it
    stays so after the block, for a dora node that outlives it (its runtime logs until the process ends)."""
    sys.stdout.flush()
    log_path.parent.mkdir(parents=True, exist_ok=True)
    with contextlib.suppress(OSError):  # a file that cannot be read or written: the open below says so
        keep_last_bytes(log_path, LOG_KEPT_BYTES)
    log_fd = os.open(log_path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    terminal_fd = os.dup(1)
    os.dup2(log_fd, 1)
    os.close(log_fd)
    if not _writes_to_descriptor_1(sys.stdout):  # already elsewhere (a test's capture): leave it there
        try:
            yield
        finally:
            os.dup2(terminal_fd, 1)
            os.close(terminal_fd)
        return
    saved_stdout = sys.stdout
    sys.stdout = io.TextIOWrapper(
        io.FileIO(terminal_fd, "w", closefd=False), encoding=saved_stdout.encoding, errors=saved_stdout.errors,
        line_buffering=True,
    )
    c_stdout = _c_stdout()
    stream = None
    if c_stdout is not None:
        libc, variable = c_stdout
        libc.fdopen.restype = ctypes.c_void_p
        libc.fdopen.argtypes = (ctypes.c_int, ctypes.c_char_p)
        libc.fflush.argtypes = libc.fclose.argtypes = (ctypes.c_void_p,)
        stream = libc.fdopen(terminal_fd, b"w")
        if stream:
            saved_c_stdout, variable.value = variable.value, stream
    try:
        yield
    finally:
        sys.stdout.flush()
        if restore:
            sys.stdout = saved_stdout
            os.dup2(terminal_fd, 1)
            if stream:
                libc.fflush(stream)
                variable.value = saved_c_stdout
                libc.fclose(stream)  # closes terminal_fd with it
            else:
                os.close(terminal_fd)


@contextlib.contextmanager
def dora_logs_aside(log_path: Path, restore: bool = True):
    """`dora_logs_to(log_path, restore)`; where that file cannot be written, one line says so and dora's
    log lines are dropped (a terminal full of JSON would be worse than none)."""
    with contextlib.ExitStack() as stack:
        try:
            stack.enter_context(dora_logs_to(log_path, restore))
        except OSError as error:
            print(f"  (dora's log lines are dropped: cannot write {log_path}: {error.strerror or error})", flush=True)
            stack.enter_context(dora_logs_to(Path(os.devnull), restore))
        yield


@contextlib.contextmanager
def stderr_to_log():
    """Inside `dora_logs_to`, descriptor 2 goes to the log file too, for the block: PyBullet
    writes its build-time banner there when first imported, not between the prompt's lines."""
    sys.stderr.flush()
    saved = os.dup(2)
    os.dup2(1, 2)
    try:
        yield
    finally:
        sys.stderr.flush()
        os.dup2(saved, 2)
        os.close(saved)


def line_editing(history_file: Path) -> Callable[[], None]:
    """Line editing for input() and a persistent history where readline exists; returns the
    function that saves the history, to call at exit."""
    try:
        import readline
    except ImportError:  # Windows without pyreadline: plain input() still works
        return lambda: None
    readline.set_history_length(1000)
    try:
        readline.read_history_file(history_file)
    except OSError:
        pass  # no history yet

    def save() -> None:
        try:
            readline.write_history_file(history_file)
        except OSError as error:
            log.warning("  (history not saved to %s: %s)", history_file, error.strerror or error)

    return save


def release_at_prompt(release: Callable[[], None]) -> bool:
    """Calls `release` each time input() has drawn its prompt (readline's pre-input hook); False where
    there is no readline, and the caller releases after its replies instead."""
    try:
        import readline
    except ImportError:
        return False

    def hook() -> None:
        try:
            release()
        except Exception as error:  # an exception here would be lost inside readline
            log.warning("  (news not shown: %s)", error)

    readline.set_pre_input_hook(hook)
    return True


# Key jogging: single key presses, straight from the terminal (termios; works over SSH, in tmux
# and headless, with no X11 keyboard hook).
_NAMED_BYTES = {b" ": "space", b"\t": "tab", b"\r": "enter", b"\n": "enter", b"\x7f": "backspace"}
_ARROWS = {b"A": "up", b"B": "down", b"C": "right", b"D": "left"}
# An Esc alone, or the start of an arrow key's sequence: the rest of a sequence comes at once.
_ESCAPE_WAIT_S = 0.05


class KeyReader:
    """Key presses from a terminal in cbreak mode (see `single_keys`): read(timeout) returns a
    one-character string, a name (space, tab, enter, esc, up, ...), or None after the timeout."""

    def __init__(self, fd: int):
        self.fd = fd
        self._pending = b""

    def _ready(self, timeout_s: float) -> bool:
        import select

        return bool(self._pending) or bool(select.select([self.fd], [], [], timeout_s)[0])

    def _take(self) -> bytes:
        if not self._pending:
            self._pending = os.read(self.fd, 64)
            if not self._pending:
                raise EOFError
        byte, self._pending = self._pending[:1], self._pending[1:]
        return byte

    def read(self, timeout_s: float) -> str | None:
        if not self._ready(timeout_s):
            return None
        byte = self._take()
        if byte == b"\x1b":
            if not self._ready(_ESCAPE_WAIT_S):
                return "esc"
            sequence = self._take()
            if sequence not in (b"[", b"O"):
                return "esc"  # Esc, then an ordinary key pressed right after it: that key is dropped
            final = self._take() if self._ready(_ESCAPE_WAIT_S) else b""
            while final and not final.isalpha() and final != b"~" and self._ready(_ESCAPE_WAIT_S):
                final = self._take()  # the parameters of a longer sequence (Home, F5, ...)
            return _ARROWS.get(final, "unknown")
        if byte in _NAMED_BYTES:
            return _NAMED_BYTES[byte]
        # A multi-byte UTF-8 character (say, from an input method) comes in one read.
        while byte[0] >= 0x80 and len(byte) < 4 and self._pending:
            try:
                return byte.decode("utf-8")
            except UnicodeDecodeError:
                byte += self._take()
        return byte.decode("utf-8", errors="replace")


@contextlib.contextmanager
def single_keys(fd: int):
    """The terminal on `fd` in cbreak mode (each key at once, no echo; Ctrl-C still interrupts)
    for the block, then exactly as it was, however the block ends: normally, Ctrl-C, an
    exception, SIGTERM or SIGHUP (both raised as KeyboardInterrupt inside the block)."""
    import signal
    import termios
    import tty

    saved = termios.tcgetattr(fd)

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    previous = {signum: signal.signal(signum, interrupt) for signum in (signal.SIGTERM, signal.SIGHUP)}
    try:
        tty.setcbreak(fd, termios.TCSANOW)
        yield KeyReader(fd)
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)
        for signum, handler in previous.items():
            signal.signal(signum, handler)
