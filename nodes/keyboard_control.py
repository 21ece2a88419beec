"""keyboard_control: the course's keyboard prompt (step D, exercise 1) as a dynamic dora node.

Start `dora run dataflow.yml` first, then in a second terminal `python nodes/keyboard_control.py`
(or both in one terminal: `so101 teleop`), and type `help` for the commands.

`dora run` gives the nodes it starts no usable terminal, so this one is `path: dynamic` and
joins the running dataflow by its id. A thread pumps the node's events (the latest
joint_state and gripper_state, and STOP) while the main thread waits for the keyboard: an
unread input queue would overflow, and dora would print a JSON warning per dropped event.
A pipe on stdin runs its lines in order and exits at its end; dora's own log lines go to a
file. What each command does is in so101/prompt/control.py; the links to the other nodes (the
recorder, the leader's news) in links.py there; the settings in settings.py.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from pathlib import Path
from typing import Callable, Sequence

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere: the so101 package sits beside nodes/
    sys.path.insert(0, str(ROOT))

from so101.prompt.control import KeyboardControl  # noqa: E402
from so101.prompt.join import join_dataflow  # noqa: E402
from so101.prompt.links import link_other_nodes  # noqa: E402
from so101.prompt.poses import PoseStore  # noqa: E402
from so101.prompt.settings import PromptSettings, environment_help  # noqa: E402
from so101.prompt.terminal import dora_logs_aside, line_editing, release_at_prompt  # noqa: E402
from so101.runtime.logs import send_diagnostics_to  # noqa: E402

NODE_ID = "keyboard_control"
_KEPT_TO_EXIT: list = []  # the joined node: see main
EVENT_WAIT_S = 0.2


def say(line: str = "") -> None:
    print(line, flush=True)


def joint_cmd_sender(node) -> Callable[[Sequence[float]], None]:
    """Sends angles (degrees) on `joint_cmd` as a float64 Arrow array."""
    import pyarrow as pa

    def send(angles_deg: Sequence[float]) -> None:
        node.send_output("joint_cmd", pa.array([float(angle) for angle in angles_deg], type=pa.float64()))

    return send


class EventPump(threading.Thread):
    """Reads the node's events until STOP or `finish()`, so no input queue ever overflows."""

    def __init__(self, node, control: KeyboardControl, on_stop: Callable[[], None]):
        super().__init__(name="dora-events", daemon=True)
        self.node, self.control, self.on_stop = node, control, on_stop
        self._finish = threading.Event()
        # Set once the events buffered before this thread started have all been read.
        self.caught_up = threading.Event()

    def run(self) -> None:
        try:
            while not self._finish.is_set():
                # First what queued before this thread started, without waiting; then each event as it comes.
                event = self.node.next(timeout=EVENT_WAIT_S) if self.caught_up.is_set() else self.node.try_recv()
                if event is None:
                    self.caught_up.set()
                    continue
                self.control.on_event(event)
                if event["type"] == "STOP":
                    if not self._finish.is_set():
                        self.on_stop()
                    return
        finally:
            self.caught_up.set()

    def finish(self) -> None:
        self._finish.set()
        self.join(timeout=2 * EVENT_WAIT_S + 1)


def run_prompt(control: KeyboardControl, interactive: bool, history_file: Path) -> None:
    """The read loop: a person at a terminal, or a script on stdin."""
    save_history = line_editing(history_file) if interactive else (lambda: None)
    # At a terminal with readline, held news is shown once the next prompt is drawn, and redraws it below;
    # shown before input() drew it, it would be drawn twice ("> > ").
    released_at_prompt = interactive and release_at_prompt(control.release_news)
    try:
        while True:
            if interactive:
                try:
                    line = input("> ")
                except EOFError:  # Ctrl-D
                    say("\n" + control.text["bye"])
                    return
            else:
                line = sys.stdin.readline()
                if not line:
                    return
                line = line.rstrip("\n")
                say(f"> {line}")
            control.hold_news()  # a node's quick answer prints below the line that asked
            replies, quit_now = control.handle_line(line)
            for reply in replies:
                say(reply)
            if not released_at_prompt:
                control.release_news()
            if quit_now:
                return
    except KeyboardInterrupt:  # Ctrl-C, or the dataflow stopped
        say("\n" + control.text["stopped" if control.stopped else "bye"])
    finally:
        save_history()


def main(argv: list[str] | None = None) -> int:
    argparse.ArgumentParser(prog="keyboard_control.py", description=__doc__, epilog=environment_help(),
                            formatter_class=argparse.RawDescriptionHelpFormatter).parse_args(argv)
    send_diagnostics_to("stderr")
    try:
        settings = PromptSettings.from_environ(os.environ)
    except ValueError as error:
        print(f"{NODE_ID}: {error}", file=sys.stderr)
        return 2
    # Not restored at the end: the node lives until the process exits (_KEPT_TO_EXIT), and its runtime
    # may log meanwhile (inputs dropped once the pump has stopped) where the terminal would show it.
    with dora_logs_aside(settings.log_file, restore=False):
        interactive = sys.stdin.isatty()
        poses = PoseStore(settings.poses_file)
        # Ctrl-C must raise KeyboardInterrupt even when started with SIGINT ignored: STOP relies on it too.
        signal.signal(signal.SIGINT, signal.default_int_handler)
        node = join_dataflow(NODE_ID, settings.daemon_port, settings.lang)
        if node is None:  # why is on stderr, in one line
            return 1
        # Kept until the process exits: a dora Node dropped before (as main returned) crashed the
        # process now and then on its way out (SIGSEGV, or glibc's "invalid stdio handle" abort).
        _KEPT_TO_EXIT.append(node)
        control = KeyboardControl(joint_cmd_sender(node), poses, settings.lang,
                                  keys_fd=sys.stdin.fileno() if interactive else None)  # `jog` reads keys there
        link_other_nodes(control, node, interactive)  # news as it comes; the recorder where there is one
        # On STOP, wake the main thread from input() or readline(): only a signal can.
        pump = EventPump(node, control, on_stop=lambda: os.kill(os.getpid(), signal.SIGINT))
        pump.start()
        try:
            pump.caught_up.wait(timeout=5)  # what queued while joining is read before the first command
        except KeyboardInterrupt:  # Ctrl-C, or STOP, while joining
            pump.finish()
            return 0
        for line in control.start_lines(interactive):
            say(line)
        try:
            run_prompt(control, interactive, settings.history_file)
        finally:
            try:
                pump.finish()
            except KeyboardInterrupt:  # STOP arrived while quitting anyway
                pass
        return 0


if __name__ == "__main__":
    sys.exit(main())
