"""MkDocs hooks: the parts of the pages that are made from the code, so they cannot drift from it.

A page asks for them with one HTML comment on a line of its own:

- `<!-- settings: so101.tasks.settings:ExpertSettings [module:Class ...] -->`: the table of the
  environment variables those settings dataclasses declare (so101/runtime/settings.py, `declared`):
  name, default and meaning, in declaration order.
- `<!-- so101-help -->`: `so101 --help` and each subcommand's `--help`, from the parser `so101` runs
  (so101/cli/main.py, `build_parser`).
- `<!-- dataflow-node: dataflow.yml simulation -->`: that node's entry, as the dataflow file has it.
- `<!-- dataflow-made: recorder -->`: a node as the `so101` commands add it to a dataflow, made by
  the code they run (so101/runtime/dataflow.py; so101/launch/lockstep.py for `so101 eval`'s).

tests/test_docs.py builds the site with `mkdocs build --strict` and holds the pages to these markers.
"""

from __future__ import annotations

import importlib
import os
import re
import sys
from pathlib import Path, PurePath

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

MARKER = re.compile(r"^<!-- (settings|so101-help|dataflow-node|dataflow-made):?(.*?) -->$", re.MULTILINE)
TABLE_HEADER = "| Environment variable | Default | Meaning |\n|---|---|---|"
HELP_COLUMNS = "100"  # argparse wraps to $COLUMNS: one width, so the page is the same on every machine


def settings_class(class_path: str) -> type:
    module, class_name = class_path.split(":")
    return getattr(importlib.import_module(module), class_name)


def default_cell(default: str, required: str) -> str:
    """An unset variable's value as the table shows it: a path under the checkout is shown relative to it."""
    if not default:
        return "empty (required)" if required else "empty"
    root = f"{ROOT}{os.sep}"
    if default.startswith(root):
        return f"`{default[len(root):]}` beside `dataflow.yml`"
    return f"`{default}`"


def settings_rows(class_paths: list[str]) -> list[tuple[str, str, str]]:
    """(variable, default cell, meaning) for each setting the classes declare, a variable once."""
    from so101.runtime.settings import declared

    rows, seen = [], set()
    for class_path in class_paths:
        for each in declared(settings_class(class_path)):
            if each.env_var not in seen:
                seen.add(each.env_var)
                rows.append((each.env_var, default_cell(each.default, each.required), each.meaning))
    return rows


def settings_table(class_paths: list[str]) -> str:
    lines = [f"| `{name}` | {default} | {meaning.replace('|', '&#124;')} |"
             for name, default, meaning in settings_rows(class_paths)]
    return "\n".join([TABLE_HEADER, *lines])


def machine_free(text: str) -> str:
    """Help text without this machine's folders: the checkout's paths relative to it, the home folder as ~."""
    home = str(Path.home())
    return (text.replace(f"{ROOT}{os.sep}", "").replace(str(ROOT), ".")
            .replace(f"{home}{os.sep}", f"~{os.sep}"))


def indented(text: str) -> str:
    text = machine_free(text)
    return "\n".join(("    " + line).rstrip() for line in text.rstrip("\n").splitlines())


def so101_help() -> str:
    """`so101 --help` and every subcommand's `--help`, each under a heading of its own."""
    from so101.cli.main import SUBCOMMANDS, build_parser

    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = HELP_COLUMNS
    try:
        parser = build_parser()
        parts = ["    $ so101 --help", indented(parser.format_help())]
        subparsers = next(action for action in parser._actions if action.choices and "teleop" in action.choices)
        for name in SUBCOMMANDS:
            parts += ["", f"## so101 {name}", "", f"    $ so101 {name} --help",
                      indented(subparsers.choices[name].format_help())]
    finally:
        if previous is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = previous
    return "\n".join(parts)


def dataflow_node(file_name: str, node_id: str) -> str:
    """The node's entry in a dataflow file, its comments kept, as a YAML block."""
    text = (ROOT / file_name).read_text(encoding="utf-8")
    start = re.search(rf"^  - id: {re.escape(node_id)}$", text, re.MULTILINE)
    if start is None:
        raise ValueError(f"{file_name} has no node {node_id!r}")
    following = re.search(r"^  - id: |^\S", text[start.end():], re.MULTILINE)
    entry = text[start.start(): start.end() + following.start() if following else len(text)]
    return f"```yaml\n# {file_name}\nnodes:\n{entry.rstrip()}\n```"


def made_node(node_id: str) -> str:
    """A node as the `so101` commands add it to dataflow.yml, with the settings they give it for the
    command named in the comment (paths relative to the checkout)."""
    import yaml

    from so101.runtime import dataflow

    root = PurePath(".")
    body = "simulation"

    def fresh() -> dict:
        return dataflow.dataflow_copy({}, root=root)

    recorder_env = {"SO101_RECORD_DIR": "out/demos", "SO101_RECORD_FPS": "30", "SO101_RECORD_IMAGE_SIZE": "320x240",
                    "SO101_LANG": "en"}
    camera_env = {"SO101_RECORD_IMAGE_SIZE": "320x240"}
    recipes = {
        "recorder": ("so101 teleop --record out/demos --lang en",
                     lambda: dataflow.with_recorder(fresh(), body, recorder_env, camera_env, 30, root=root)),
        "camera": ("so101 teleop --record out/demos --lang en",
                   lambda: dataflow.with_recorder(fresh(), body, recorder_env, camera_env, 30, root=root)),
        "expert": ("so101 teleop --task cube_to_box --lang en",
                   lambda: dataflow.with_expert(dataflow.with_task(fresh(), body, "cube_to_box", 0), body,
                                                {"SO101_TASK": "cube_to_box", "SO101_LANG": "en"}, root=root)),
        "web_view": ("so101 teleop --web",
                     lambda: dataflow.with_web_view(fresh(), body, {"SO101_WEB_HOST": "127.0.0.1",
                                                                    "SO101_WEB_PORT": "8101"}, root=root)),
        "replay": ("so101 replay out/demos --episode 0",
                   lambda: dataflow.with_replay(fresh(), body)),
        "policy": ("so101 teleop --task cube_to_box --policy DIR",
                   lambda: dataflow.with_policy(
                       dataflow.with_task(fresh(), body, "cube_to_box", 0), body,
                       ("joint_state", "gripper_state", "object_state"),
                       {"SO101_POLICY_DIR": "DIR", "SO101_POLICY_DEVICE": "cpu", "SO101_TASK": "cube_to_box",
                        "SO101_LOCKSTEP_PICTURES": "", "SO101_LANG": "en"},
                       policy_python(), root=root)),
        "perception": ("so101 teleop --task cube_to_box --policy DIR (a seeing recipe)",
                       lambda: dataflow.with_perception(
                           dataflow.with_policy(
                               dataflow.with_camera(dataflow.with_task(fresh(), body, "cube_to_box", 0), body,
                                                    {"SO101_RECORD_IMAGE_SIZE": "160x120"}, 25, root=root),
                               body, ("joint_state", "gripper_state", "object_state"),
                               {"SO101_POLICY_DIR": "DIR/policy", "SO101_POLICY_DEVICE": "cpu",
                                "SO101_TASK": "cube_to_box", "SO101_LOCKSTEP_PICTURES": "", "SO101_LANG": "en"},
                               policy_python(), root=root),
                           body, {"SO101_EYES_DIR": "DIR/eyes", "SO101_TASK": "cube_to_box", "SO101_LANG": "en"},
                           policy_python(), root=root)),
    }
    if node_id == "episodes":
        return eval_dataflow()
    if node_id == "camera_front":  # a real camera of the real arm's dataflow
        from so101.launch.real_cameras import add_real_cameras

        real = dataflow.dataflow_copy({}, dataflow.ROOT / "dataflow_real.yml", root=root)
        add_real_cameras(real, {"front": "/dev/video0"}, (640, 480), (640, 480), 30, root=root)
        node = next(each for each in real["nodes"] if each["id"] == node_id)
        text = yaml.safe_dump({"nodes": [node]}, sort_keys=False, allow_unicode=True)
        command = "so101 teleop --body real --camera front=/dev/video0 ..."
        return f"```yaml\n# the node `{command}` adds to dataflow_real.yml\n{text.rstrip()}\n```"
    command, make = recipes[node_id]
    node = next(each for each in make()["nodes"] if each["id"] == node_id)
    text = yaml.safe_dump({"nodes": [node]}, sort_keys=False, allow_unicode=True)
    return f"```yaml\n# the node `{command}` adds to dataflow.yml\n{text.rstrip()}\n```"


def policy_python() -> str:
    """so101 policy-env's interpreter, in the user's cache, written from the home folder (~): the command
    writes the full path."""
    from so101.policy.environment import default_dir, python_in

    return machine_free(str(python_in(default_dir())))


def eval_dataflow() -> str:
    """The whole lockstep dataflow `so101 eval --task cube_to_box --expert` runs: body, expert, episodes."""
    import tempfile

    import yaml

    from so101.launch.lockstep import expert_driver, flows_for, lockstep_dataflow
    from so101.cli.main import build_parser

    args = build_parser().parse_args(["eval", "--task", "cube_to_box", "--expert", "--lang", "en"])
    with tempfile.TemporaryDirectory() as work:
        (flow,) = flows_for(args, Path(work), expert_driver(args), ("image",), None,
                            lambda folder: {"SO101_VIDEO_DIR": ""})
        text = yaml.safe_dump(lockstep_dataflow(flow, root=PurePath(".")), sort_keys=False, allow_unicode=True)
        text = text.replace(work, "out/eval-DATE-PID")
    return (f"```yaml\n# as so101 eval --task cube_to_box --expert --lang en writes it (so101/launch/lockstep.py)\n"
            f"{text.rstrip()}\n```")


def expand(markdown: str) -> str:
    def one(match: re.Match[str]) -> str:
        kind, arguments = match.group(1), match.group(2).split()
        if kind == "settings":
            return settings_table(arguments)
        if kind == "so101-help":
            return so101_help()
        if kind == "dataflow-node":
            return dataflow_node(*arguments)
        return made_node(*arguments)

    return MARKER.sub(one, markdown)


def on_page_markdown(markdown: str, page, config, files) -> str:  # noqa: ANN001 (MkDocs' hook signature)
    return expand(markdown)
