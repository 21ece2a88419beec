"""The documentation site builds: `mkdocs build --strict` fails on a broken link or anchor, a page missing
from the navigation, or a marker docs/hooks.py cannot fill; and what the hooks fill in is the code's."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest
import yaml

from tests.helpers.dataflow import ROOT
from tests.helpers.docs import DOCS, hooks, pages


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    site_dir = tmp_path_factory.mktemp("site")
    built = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site_dir)],
        cwd=ROOT, capture_output=True, text=True, timeout=300,
        env=dict(os.environ, NO_MKDOCS_2_WARNING="1"),
    )
    assert built.returncode == 0, built.stdout + built.stderr
    assert "WARNING" not in built.stderr, built.stderr
    return site_dir


@pytest.mark.slow  # mkdocs runs for seconds
def test_the_site_builds_strictly_with_every_page(site):
    for page in pages():
        built = site / (page.removesuffix(".md").removesuffix("index") + "/index.html").lstrip("/")
        assert built.exists(), page
    assert (site / "search" / "search_index.json").exists()


@pytest.mark.slow
def test_every_marker_is_filled_in(site):
    for html in site.rglob("*.html"):
        assert not re.search(r"<!-- (settings|so101-help|dataflow-node|dataflow-made)", html.read_text()), html


def test_every_page_is_in_the_navigation():
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))

    def listed(entries):
        for entry in entries:
            values = entry.values() if isinstance(entry, dict) else [entry]
            for value in values:
                yield from (listed(value) if isinstance(value, list) else [value])

    assert sorted(listed(config["nav"])) == sorted(pages())


def test_the_pictures_are_shown():
    shown = {name for text in pages().values() for name in re.findall(r"\]\((?:\.\./)*([\w-]+\.png)\)", text)}
    assert shown == {path.name for path in DOCS.glob("*.png")}


def test_the_commands_page_is_so101s_own_help():
    from so101.cli.main import SUBCOMMANDS

    made = hooks().so101_help()
    assert made.startswith("    $ so101 --help\n    usage: so101 [-h] COMMAND ...")
    for name, (_, summary) in SUBCOMMANDS.items():
        assert f"\n## so101 {name}\n" in made and f"    usage: so101 {name} " in made
        assert " ".join(summary.split()[:4]) in made
    assert str(ROOT) not in made


def test_the_dataflow_entries_are_the_files_and_the_commands_own():
    made = hooks().dataflow_node("dataflow.yml", "simulation")
    entry = yaml.safe_load(made.removeprefix("```yaml\n").removesuffix("\n```"))["nodes"]
    described = yaml.safe_load((ROOT / "dataflow.yml").read_text(encoding="utf-8"))["nodes"]
    assert entry == [node for node in described if node["id"] == "simulation"]
    for node_id in ("recorder", "camera", "expert", "web_view", "replay", "policy", "perception", "episodes"):
        made = hooks().made_node(node_id)
        nodes = yaml.safe_load(made.removeprefix("```yaml\n").removesuffix("\n```"))["nodes"]
        node = next(each for each in nodes if each["id"] == node_id)
        launched = node.get("args", node["path"])
        assert launched == "dynamic" or (ROOT / launched).exists(), (node_id, launched)
