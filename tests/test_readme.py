"""The README tells the truth about the tree: every file it names exists, every `so101` subcommand is real."""

from __future__ import annotations

import re

import pytest

from so101.cli.main import SUBCOMMANDS
from tests.helpers.dataflow import ROOT

README = (ROOT / "README.md").read_text(encoding="utf-8")

# The project's folders (and the set-up's): a path in the README that starts with one must exist.
PROJECT_FOLDERS = ("so101", "nodes", "tests", "examples", "bench", "docs", "assets", ".ci", ".venv")
# path, or path::test_name
TOKEN = re.compile(r"[\w.*/-]+(?:::\w+)?")


def code_spans() -> list[str]:
    """Inline code, indented blocks and image links: where the README names files and commands."""
    indented = re.compile(r"^ {4,}(\S.*)$", re.M)  # quoted output may hold backticks of its own
    return (re.findall(r"`([^`]+)`", indented.sub("", README)) + indented.findall(README)
            + re.findall(r"\]\(([^)#]+)\)", README))


def named_paths() -> list[tuple[str, str | None]]:
    found = []
    for code in code_spans():
        for token in TOKEN.findall(code):
            path, _, test_name = token.partition("::")
            if "/" in path and path.split("/")[0] in PROJECT_FOLDERS:
                found.append((path.rstrip("."), test_name or None))
    return found


def test_the_readme_names_files_that_exist():
    paths = named_paths()
    assert len(paths) > 30  # the pattern still finds them
    missing = sorted({path for path, _ in paths if not list(ROOT.glob(path.rstrip("/")))})
    assert missing == []


def test_the_tests_the_readme_cites_exist():
    cited = [(path, name) for path, name in named_paths() if name]
    assert cited
    for path, name in cited:
        assert re.search(rf"^def {name}\(", (ROOT / path).read_text(), re.M), f"{path}::{name}"


def test_every_so101_command_in_the_readme_exists():
    used = {name for code in code_spans() for name in re.findall(r"(?:^|\s)so101 ([a-z][a-z-]*)", code)}
    assert {"assets", "inspect", "joints", "teleop", "plot-step", "snapshot", "bench", "fake-arm", "calibrate"} <= used
    assert used <= set(SUBCOMMANDS), used - set(SUBCOMMANDS)


@pytest.mark.parametrize("body", ["pybullet", "mujoco", "real", "cluster"])
def test_the_benchmark_tables_in_the_readme_are_the_latest_results(body):
    import json

    from bench import cluster_bench, real_bench, run_bench

    latest = run_bench.DEFAULT_OUT[body]
    result = json.loads(latest.read_text())
    table = {"real": real_bench.table, "cluster": cluster_bench.table}.get(body, run_bench.table)
    shown = "\n".join(("    " + line).rstrip() for line in table(result).splitlines())
    assert shown in README, f"README's benchmark figures differ from {latest.name} (so101 bench --show prints them)"


SUITE_LINES = {  # the README's Tests section: each command's time and how many tests it ran
    "": re.compile(r"python3\.11 bootstrap\.py test .*: [\d a-z]+ here \((\d+) tests\)"),
    "not slow": re.compile(r"\.venv/bin/pytest -m \"not slow\" .*: [\d a-z]+ \((\d+) tests\)"),
}


def test_the_suite_times_in_the_readme_are_from_a_run_of_about_todays_suite():
    """A time quoted for a suite of 544 tests, when it has 805, is a figure from another project."""
    import subprocess
    import sys

    # One collection gives both counts: "685/1025 tests collected (340 deselected)".
    collected = subprocess.run(
        [sys.executable, "-m", "pytest", "--collect-only", "-q", "-m", "not slow"],
        cwd=ROOT, capture_output=True, text=True, check=True,
    ).stdout
    fast, whole = map(int, re.search(r"^(\d+)/(\d+) tests collected", collected, re.MULTILINE).groups())
    for marks, count in (("", whole), ("not slow", fast)):
        quoted = SUITE_LINES[marks].search(README)
        assert quoted, f"README's Tests section has no time with its test count for {marks or 'the whole suite'!r}"
        # Within a tenth: a few tests added since the timed run are fine, another era's figure is not.
        assert abs(int(quoted.group(1)) - count) <= count / 10, (quoted.group(0), count)
