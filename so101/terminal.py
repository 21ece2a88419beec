"""Keep dora's own log lines out of the prompt's terminal, for the whole session.

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
import os
import sys
from pathlib import Path

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
def dora_logs_to(log_path: Path):
    """Descriptor 1 goes to `log_path` (appended) inside the block; Python's prints and the
    line editor go to the terminal as before."""
    sys.stdout.flush()
    log_path.parent.mkdir(parents=True, exist_ok=True)
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
        sys.stdout = saved_stdout
        os.dup2(terminal_fd, 1)
        if stream:
            libc.fflush(stream)
            variable.value = saved_c_stdout
            libc.fclose(stream)  # closes terminal_fd with it
        else:
            os.close(terminal_fd)
