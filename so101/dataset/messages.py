"""The `record_cmd` message between the prompt and the recorder: JSON text, so the prompt needs
neither numpy nor the dataset code to send one."""

from __future__ import annotations

import json
from dataclasses import dataclass

COMMANDS = ("record", "stop", "discard", "episodes", "toggle")


@dataclass
class RecordCommand:
    """A `record_cmd` message: {"command": one of COMMANDS, "task": text for record/toggle}."""

    command: str
    task: str = ""


def decode_record_cmd(text: str) -> RecordCommand | str:
    """A record_cmd's JSON text -> the command, or the reason it is not one (one line)."""
    try:
        message = json.loads(text)
        command = message["command"]
        task = str(message.get("task", "")).strip()
    except (ValueError, TypeError, KeyError):
        return f"not a record_cmd: {text[:80]!r}"
    return RecordCommand(command, task)


def encode_record_cmd(command: str, task: str = "") -> str:
    return json.dumps({"command": command, "task": task}, ensure_ascii=False)


# `record_status` metadata: the episode recording (-1: none) and its task, sent with every status.
RECORDING_EPISODE_KEY = "recording_episode"
RECORDING_TASK_KEY = "recording_task"


def recording_metadata(recording: tuple[int, str] | None) -> dict[str, int | str]:
    episode, task = recording if recording is not None else (-1, "")
    return {RECORDING_EPISODE_KEY: episode, RECORDING_TASK_KEY: task}


def recording_from_metadata(metadata: dict) -> tuple[int, str] | None:
    """(episode, task) of the episode recording, or None: from a `record_status`'s metadata."""
    try:
        episode = int(metadata.get(RECORDING_EPISODE_KEY, -1))
    except (TypeError, ValueError):
        return None
    return (episode, str(metadata.get(RECORDING_TASK_KEY, ""))) if episode >= 0 else None
