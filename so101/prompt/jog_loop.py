"""The `jog` command at a terminal: read a key, apply it (so101/prompt/jog.py says what each key
does), send at most one joint_cmd per joint_state received, redraw the status line in place.

Imported when `jog` is first typed: the prompt starts without it.
"""

from __future__ import annotations

import os
import sys
from typing import Any, Protocol, Sequence

from dataclasses import replace

from so101.prompt.jog import EPISODE_KEY, TEXT, Jog, press, status_line
from so101.prompt.terminal import single_keys
from so101.robot import NUM_ARM_JOINTS

# Look for a key this often, and send a waiting command once a newer joint_state came.
JOG_POLL_S = 0.01


class JogPrompt(Protocol):
    """What jogging needs of the prompt (so101.prompt.control.KeyboardControl, which imports this
    module only when `jog` is typed)."""

    lang: str
    text: dict[str, str]
    states_seen: int
    news_shown: int  # lines printed over the status line meanwhile (the recorder's news)

    def send_joint_cmd(self, angles_deg: Sequence[float]) -> None: ...

    def wait_for_state(self, timeout_s: float) -> tuple[tuple[float, ...] | None, float | None]: ...

    def latest_deg(self) -> tuple[float, ...] | None: ...

    def kinematics(self) -> Any: ...

    def ask_recorder(self, command: str, task: str = "") -> list[str]: ...


def _columns(fd: int) -> int:
    """The terminal's width (fd 1 is dora's log file here, so ask the keyboard's terminal)."""
    try:
        return os.get_terminal_size(fd).columns
    except OSError:
        return 80


def run_jog(control: JogPrompt, fd: int, first_state_wait_s: float) -> list[str]:
    """Key jogging at the terminal on `fd` until Esc or q; returns the closing lines. At most one
    joint_cmd per joint_state received, so holding a key never queues commands ahead of the arm.
    The terminal is restored however this ends."""
    text = control.text
    control.wait_for_state(first_state_wait_s)
    start_deg = control.latest_deg()
    if start_deg is None:
        return [text["jog_no_state"]]
    jog_text = TEXT[control.lang]
    print("\n".join(jog_text["map"]), flush=True)
    jog = Jog(targets_deg=start_deg)
    kinematics = None  # made when Cartesian mode is first asked for: it loads PyBullet
    waiting_deg, sent_at_state, shown = None, -1, ""
    news_seen = control.news_shown
    try:
        with single_keys(fd) as keys:
            while True:
                key = keys.read(JOG_POLL_S)
                if key is not None and key.lower() == EPISODE_KEY:  # the recorder's answer, on the status line
                    jog = replace(jog, note=control.ask_recorder("toggle")[0].strip())
                elif key is not None:
                    if key == "tab" and kinematics is None:
                        kinematics = control.kinematics()
                    pressed = press(jog, key, control.latest_deg(), kinematics, control.lang)
                    jog = pressed.jog
                    if pressed.leave:
                        break
                    if pressed.show_map:
                        sys.stdout.write("\r\x1b[K" + "\n".join(jog_text["map"]) + "\n")
                        shown = ""
                    if pressed.send_deg is not None:
                        waiting_deg = pressed.send_deg
                if waiting_deg is not None and control.states_seen != sent_at_state:
                    control.send_joint_cmd(list(waiting_deg))
                    waiting_deg, sent_at_state = None, control.states_seen
                state_deg = control.latest_deg()
                tip_mm = None
                if jog.cartesian and kinematics is not None and state_deg:  # Tab has made the kinematics
                    tip_mm = kinematics.tip_mm(state_deg[:NUM_ARM_JOINTS])
                line = status_line(jog, state_deg, tip_mm, control.lang)[: _columns(fd) - 1]
                if control.news_shown != news_seen:  # a line was printed where the status line was
                    news_seen, shown = control.news_shown, ""
                if line != shown:
                    sys.stdout.write("\r\x1b[K" + line)
                    sys.stdout.flush()
                    shown = line
    except EOFError:  # the terminal went away
        pass
    finally:
        sys.stdout.write("\n")
        sys.stdout.flush()
    return [text["jog_left"]]
