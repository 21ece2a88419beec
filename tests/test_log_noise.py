"""dora's log lines around the prompt (issue 23): the prompt drops no state while it waits for the CPU
(so writes no warning line per drop), and the file those lines go to stays bounded across sessions."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time

import pytest

from so101.prompt.terminal import LOG_KEPT_BYTES, dora_logs_to
from so101.runtime.logs import keep_last_bytes
from tests.helpers.dataflow import PROMPT_COMMAND, DoraRun, prompt_env, write_test_dataflow


def numbered_lines(count: int, first: int = 0) -> bytes:
    return b"".join(b"line %06d of a dora warning\n" % number for number in range(first, first + count))


LINE_BYTES = len(numbered_lines(1))


@pytest.mark.parametrize(
    ("content", "max_bytes", "kept"),
    [
        # cut at a line's start: the line cut in two goes whole
        (numbered_lines(100), 10 * LINE_BYTES + 5, numbered_lines(10, first=90)),
        (numbered_lines(100), 10 * LINE_BYTES, numbered_lines(10, first=90)[LINE_BYTES:]),
        (numbered_lines(3), 1000, numbered_lines(3)),  # within the bound: untouched
        (b"x" * 50, 20, b"x" * 20),  # one line longer than the bound: its end
    ],
    ids=["mid-line", "at-a-line-start", "small", "one-long-line"],
)
def test_keep_last_bytes_keeps_the_last_whole_lines(tmp_path, content, max_bytes, kept):
    log_file = tmp_path / "prompt.log"
    log_file.write_bytes(content)
    keep_last_bytes(log_file, max_bytes)
    assert log_file.read_bytes() == kept


def test_keep_last_bytes_leaves_a_missing_file_missing(tmp_path):
    keep_last_bytes(tmp_path / "none.log", 10)
    assert not (tmp_path / "none.log").exists()


def test_the_prompt_log_stays_bounded_across_sessions(tmp_path):
    """Each session (dora_logs_to, as the prompt runs it) appends what dora writes to descriptor 1;
    the file never holds more than the bound plus one session's lines."""
    log_file = tmp_path / "keyboard_control.log"
    log_file.write_bytes(numbered_lines(3 * LOG_KEPT_BYTES // LINE_BYTES))  # a log grown by earlier sessions
    session_lines = numbered_lines(LOG_KEPT_BYTES // 2 // LINE_BYTES)
    for session in range(4):
        with dora_logs_to(log_file):
            os.write(1, session_lines)
        size = log_file.stat().st_size
        assert LOG_KEPT_BYTES - LINE_BYTES < size <= LOG_KEPT_BYTES + len(session_lines), (session, size)
        assert log_file.read_bytes().endswith(session_lines)


# A drop out of one of the prompt's input queues, as dora's node runtime logs it (two wordings).
STATE_DROP = re.compile(r"Discarding event for input `(joint_state|gripper_state)`|dropping zenoh input")


@pytest.mark.dataflow
def test_a_prompt_held_up_drops_no_state_and_shows_the_latest(tmp_path, no_other_dataflow):
    """The prompt stopped for 0.2 s at a time (SIGSTOP: a busy machine, for certain): 50 states
    of each kind arrive meanwhile; its queues hold them, so dora logs no drop, and `state` still
    shows where the arm is now."""
    dora = DoraRun(write_test_dataflow(tmp_path, {"SO101_LANG": "en"}), tmp_path / "dora.log")
    prompt = None
    try:
        dora.wait_for("SO-101 loaded", timeout_s=60)
        prompt = subprocess.Popen(PROMPT_COMMAND, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                  stderr=subprocess.STDOUT, env=prompt_env(tmp_path), text=True)
        prompt.stdin.write("0 77\n")
        prompt.stdin.flush()
        time.sleep(2)  # the prompt joins and the arm turns (half a second)
        for _ in range(3):
            prompt.send_signal(signal.SIGSTOP)
            time.sleep(0.2)
            prompt.send_signal(signal.SIGCONT)
            time.sleep(0.5)
        output, _ = prompt.communicate("state\nquit\n", timeout=30)
    finally:
        if prompt is not None and prompt.poll() is None:
            prompt.kill()
        dora.stop()
    angles = re.search(r"^  joint angles now: \[(.*?)\]°", output, re.M)
    assert angles, output
    assert float(angles.group(1).split(",")[0]) == pytest.approx(77.0, abs=1.0)
    drops = [line for line in (tmp_path / "prompt.log").read_text(errors="replace").splitlines()
             if STATE_DROP.search(line)]
    assert drops == []
