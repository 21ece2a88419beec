"""The prompt's links to the dataflow's other nodes, each where the dataflow declares it.

News (the recorder's, the leader's on `leader_status`, the expert's on `expert_status`, the policy's
on `policy_status`, where the tip landed after `xyz`, the cube landing in the box) is printed as it
comes, between the person's lines; `record_cmd`, where the dataflow has a recorder, is the line to
it; `task_cmd`, where the body runs a task, the line to the body; `expert_cmd` the line to the
task's expert, `policy_cmd` the line to the policy. A command that talks to another node wires its output in `link_other_nodes`,
so nodes/keyboard_control.py stays the course's file.
"""

from __future__ import annotations

import sys
from typing import Callable

from so101.prompt.control import KeyboardControl
from so101.prompt.recorder_link import RecorderLink
from so101.prompt.task_link import TaskLink, TaskStatus


def link_other_nodes(control: KeyboardControl, node, interactive: bool) -> None:
    """Gives `control` what the joined `node`'s dataflow offers beyond joint_cmd and the states."""
    control.show_news = news_printer(control, interactive)
    control.recorder = recorder_link(node, control.news)
    control.task = task_link(node, control.task_news)
    control.tell_expert = word_sender(node, "expert_cmd")
    control.tell_policy = word_sender(node, "policy_cmd")


def has_output(node, output_id: str) -> bool:
    return output_id in (node.node_config() or {}).get("outputs", [])


def news_printer(control: KeyboardControl, interactive: bool) -> Callable[[str], None]:
    """Prints news while the person types or jogs: on a line of its own, then the prompt (or jog's
    status line) drawn again below it."""

    def show(line: str) -> None:
        if not interactive:
            print(line, flush=True)
            return
        sys.stdout.write(f"\r\x1b[K{line}\n")
        if control.jogging:
            control.news_shown += 1  # the jog loop draws its status line again
        else:
            try:
                import readline

                typed = readline.get_line_buffer()
            except ImportError:
                typed = ""
            sys.stdout.write(f"> {typed}")  # readline's own state is unchanged
        sys.stdout.flush()

    return show


def request_sender(node, output_id: str) -> Callable[[str, str], None] | None:
    """What sends a command line on `output_id` with its request number in the metadata (the other
    node answers with it in `reply_to`), where the dataflow declares that output; else None."""
    if not has_output(node, output_id):
        return None
    import pyarrow as pa

    def send(text: str, request: str) -> None:
        node.send_output(output_id, pa.array([text]), {"request": request})

    return send


def recorder_link(node, show: Callable[[str], None]) -> RecorderLink | None:
    """The line to the recorder, where the dataflow has one (`so101 teleop --record`)."""
    send = request_sender(node, "record_cmd")
    return RecorderLink(send, show) if send is not None else None


def task_link(node, on_news: Callable[[TaskStatus, str], None]) -> TaskLink | None:
    """The line to a body running a task, where the dataflow has one (`so101 teleop --task`)."""
    send = request_sender(node, "task_cmd")
    return TaskLink(send, on_news) if send is not None else None


def word_sender(node, output_id: str) -> Callable[[str], None] | None:
    """What sends a word on `output_id`: to the task's expert (`expert_cmd`, `so101 teleop --task`) or the
    policy (`policy_cmd`, `so101 teleop --policy`), where the dataflow has one."""
    if not has_output(node, output_id):
        return None
    import pyarrow as pa

    return lambda word: node.send_output(output_id, pa.array([word]))
