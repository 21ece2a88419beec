"""The terminal a person types in: a tmux session driven with send-keys and read with capture-pane,
`so101 teleop` and `so101 calibrate` started in one as a person starts them."""

from __future__ import annotations

import os
import re
import subprocess
import time
import uuid
from pathlib import Path

from tests.helpers.dataflow import SO101


# The prompt ready for typing: the banner's last rule, any news printed since (each line indented,
# such as a leader that missed reads while the machine was busy), then `>`.
PROMPT_READY = r"^=+\n(?:  .*\n)*>$"


class Terminal:
    """One tmux session of 200x50 running a shell command; the pane stays after the command exits."""

    def __init__(self, command: str, env: dict[str, str]):
        self.name = f"so101-test-{uuid.uuid4().hex[:8]}"
        exports = " ".join(f"{key}='{value}'" for key, value in env.items())
        subprocess.run(
            ["tmux", "new-session", "-d", "-s", self.name, "-x", "200", "-y", "50",
             f"env {exports} {command}; echo TELEOP_EXIT=$?; sleep 600"],
            check=True,
        )
        self.seen = 0  # screen text up to here is answered: `command` looks for replies past it

    def screen(self) -> str:
        result = subprocess.run(
            ["tmux", "capture-pane", "-p", "-J", "-S", "-500", "-t", self.name], capture_output=True, text=True,
        )
        # -J keeps trailing blanks; a person does not see them
        return "\n".join(line.rstrip() for line in result.stdout.splitlines())

    def wait_for_prompt(self, timeout_s: float = 60) -> re.Match:
        return self.wait_for(PROMPT_READY, timeout_s=timeout_s)

    def type_line(self, text: str) -> None:
        # -l: literal text, or tmux reads "home" as the Home key
        subprocess.run(["tmux", "send-keys", "-t", self.name, "-l", text], check=True)
        subprocess.run(["tmux", "send-keys", "-t", self.name, "Enter"], check=True)

    def wait_for(self, pattern: str, timeout_s: float = 60, after: int = 0) -> re.Match:
        """The first match of `pattern` in the screen text past offset `after` (waits for it to appear)."""
        deadline = time.monotonic() + timeout_s
        while True:
            screen = self.screen()
            match = re.compile(pattern, re.M).search(screen, after)
            if match:
                return match
            if time.monotonic() > deadline:
                raise AssertionError(f"{pattern!r} not on the screen within {timeout_s}s:\n{screen}")
            time.sleep(0.2)

    def command(self, text: str, reply: str, timeout_s: float = 20) -> re.Match:
        """Once the prompt `>` shows past `seen`, type `text` and wait for `reply` (a pattern) right below it.
        A person types when they see the prompt: keys typed before it is printed are echoed ahead of it."""
        self.wait_for(r"^>$", timeout_s, after=self.seen)
        self.type_line(text)
        match = self.wait_for(rf"^> {re.escape(text)}\n{reply}$", timeout_s, after=self.seen)
        self.seen = match.end()
        return match

    def close(self, wait_s: float = 60.0) -> None:
        """Closes the terminal (its command gets SIGHUP, as when a person closes the window) and waits until
        every process started in it is gone: a dataflow still stopping holds the port the next test's prompt takes."""
        panes = subprocess.run(["tmux", "list-panes", "-t", self.name, "-F", "#{pane_pid}"], capture_output=True,
                               text=True).stdout.split()
        started = descendants(int(panes[0])) if panes else set()
        subprocess.run(["tmux", "kill-session", "-t", self.name], capture_output=True)
        deadline = time.monotonic() + wait_s
        while started and time.monotonic() < deadline:
            started = {pid for pid in started if alive(pid)}
            time.sleep(0.2)


def alive(pid: int) -> bool:
    """Whether `pid` runs (a zombie waiting to be reaped does not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def descendants(pid: int) -> set[int]:
    """The processes below `pid`, and `pid` itself (Linux /proc)."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    found, todo = set(), [pid]
    while todo:
        found.add(todo[-1])
        todo.extend(child for child in children.get(todo.pop(), []) if child not in found)
    return found


def start_teleop(tmp_path: Path, lang: str, mode: str = "direct", body: str = "pybullet", extra: str = "",
                 **env: str) -> tuple[Terminal, Path, Path]:
    """`so101 teleop` (headless by default; `extra`: more options) in a new terminal; returns it, the poses
    file and the dataflow's log."""
    poses_file = tmp_path / "poses.json"
    log_file = tmp_path / "dora.log"
    env = {
        "SO101_POSES_FILE": str(poses_file), "SO101_HISTORY_FILE": str(tmp_path / "history"),
        "SO101_PROMPT_LOG": str(tmp_path / "prompt.log"), "SO101_LANG": lang, "PATH": os.environ["PATH"], **env,
    }
    command = f"{SO101} teleop --body {body} --mode {mode} --lang {lang} --log {log_file} {extra}".rstrip()
    return Terminal(command, env), poses_file, log_file


def calibrate_in_tmux(fake_arm: Terminal, calibration_file: Path, *options: str) -> str:
    """`so101 calibrate` in a second terminal on the port `fake_arm` (a `so101 fake-arm` terminal)
    printed, as a person does it: Enter, `sweep` in the emulator's terminal, Enter. Returns the port."""
    port = fake_arm.wait_for(r"^(/dev/\S+)$", timeout_s=30).group(1)
    calibrate = Terminal(f"{SO101} calibrate --port {port} --out {calibration_file} {' '.join(options)}",
                         {"PATH": os.environ["PATH"], "SO101_LANG": "en"})
    try:
        calibrate.wait_for(r"Then press Enter\.", timeout_s=30)
        calibrate.type_line("")
        calibrate.wait_for(r"Press Enter when done\.", timeout_s=30)
        fake_arm.wait_for(r"a calibration has begun on this bus: .* type sweep here", timeout_s=10)  # the emulator's hint
        fake_arm.type_line("sweep 2")  # the emulated hand takes each joint to both of its stops
        time.sleep(2.5)
        calibrate.type_line("")
        calibrate.wait_for(r"^TELEOP_EXIT=0$", timeout_s=30)
        assert f"Wrote {calibration_file}:" in calibrate.screen()
    finally:
        calibrate.close()
    return port


def send_keys(terminal: Terminal, *keys: str) -> None:
    subprocess.run(["tmux", "send-keys", "-t", terminal.name, *keys], check=True)
