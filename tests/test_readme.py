"""The README and the documentation site (docs/) tell the truth about the tree: every file they name exists,
every `so101` subcommand is real, the figures they quote are the latest; and the README stays a front page."""

from __future__ import annotations

import re

import pytest

from so101.cli.main import SUBCOMMANDS
from tests.helpers.dataflow import ROOT
from tests.helpers.docs import docs_text, page_text, pages

README = (ROOT / "README.md").read_text(encoding="utf-8")
DOCS = docs_text()  # the README and every page of the site
INDENTED = re.compile(r"^ {4,}(\S.*)$", re.M)  # a quoted block: its output may hold backticks, its commands `#`

# The project's folders (and the set-up's): a path in the docs that starts with one must exist.
PROJECT_FOLDERS = ("so101", "nodes", "tests", "examples", "bench", "docs", "assets", ".ci", ".venv")
# path, or path::test_name
TOKEN = re.compile(r"[\w.*/-]+(?:::\w+)?")


def code_spans() -> list[str]:
    """Inline code, indented blocks and the README's links: where the docs name files and commands (the
    pages' own links are relative to the page, and `mkdocs build --strict` checks them: tests/test_docs.py)."""
    spans = [span for text in (README, *pages().values())
             for span in re.findall(r"`([^`]+)`", INDENTED.sub("", text)) + INDENTED.findall(text)]
    return spans + re.findall(r"\]\(([^)#]+)\)", README)


GYMNASIUM_ID = re.compile(r"^\w+/[A-Z]\w*-v\d+$")  # namespace/Name-vN


def named_paths() -> list[tuple[str, str | None]]:
    found = []
    for code in code_spans():
        for token in TOKEN.findall(code):
            path, _, test_name = token.partition("::")
            if GYMNASIUM_ID.match(path):  # so101/CubeToBox-v0 names an environment, not a file
                continue
            if "/" in path and path.split("/")[0] in PROJECT_FOLDERS:
                found.append((path.rstrip("."), test_name or None))
    return found


def test_the_docs_name_files_that_exist():
    paths = named_paths()
    assert len(paths) > 30  # the pattern still finds them
    missing = sorted({path for path, _ in paths if not list(ROOT.glob(path.rstrip("/")))})
    assert missing == []


def test_the_tests_the_docs_cite_exist():
    cited = [(path, name) for path, name in named_paths() if name]
    assert cited
    for path, name in cited:
        assert re.search(rf"^def {name}\(", (ROOT / path).read_text(), re.M), f"{path}::{name}"


def test_every_so101_command_in_the_docs_exists():
    used = {name for code in code_spans() for name in re.findall(r"(?:^|\s)so101 ([a-z][a-z-]*)", code)}
    assert {"assets", "inspect", "joints", "teleop", "plot-step", "snapshot", "bench", "fake-arm", "calibrate"} <= used
    assert used <= set(SUBCOMMANDS), used - set(SUBCOMMANDS)


def test_the_benchmark_tables_in_the_docs_are_the_latest_results():
    """Every saved result of `so101 bench` is quoted whole, as `--show` prints it (its date and machine
    first): a figure the docs cite is the one in bench/results/ (tests/test_bench.py holds those newer than
    the code they measure)."""
    import json

    from bench import run_bench

    for latest in run_bench.DEFAULT_OUT.values():
        shown = "\n".join(("    " + line).rstrip() for line in run_bench.table_of(json.loads(latest.read_text())).splitlines())
        assert shown in DOCS, f"the docs' benchmark figures differ from {latest.name} (so101 bench --show prints them)"


def quoted_rows() -> list[tuple[str, str]]:
    """(page, row) for each how-to table row that repeats a saved benchmark's figures."""
    import json

    from bench import run_bench

    saved = {key: json.loads(path.read_text()) for key, path in run_bench.DEFAULT_OUT.items()}
    demos = {body: saved[key]["demos"]["runs"] for body, key in (("pybullet", "demos"), ("mujoco", "demos-mujoco"))}
    rows = [("loop/demos.md", f"| 20 demonstrations (seeds 1000 on), no video, 1 worker | "
                              f"{demos['pybullet']['no_video_1_workers']['times_real_time']:.1f}× real time on PyBullet, "
                              f"{demos['mujoco']['no_video_1_workers']['times_real_time']:.1f}× on MuJoCo |"),
            ("loop/demos.md", f"| 4 demonstrations (seeds 1000 on) with both cameras at 320×240, 2 workers | "
                              f"{demos['pybullet']['video_2_workers']['times_real_time']:.1f}× real time on PyBullet, "
                              f"{demos['mujoco']['video_2_workers']['times_real_time']:.1f}× on MuJoCo |")]
    cameras = [saved["cameras"]["cameras"], saved["cameras-mujoco"]["cameras"]]
    keys = ("observation.images.front", "observation.images.wrist")
    cells = {
        "a picture alone (ms, p50)": [f"{each['alone'][key]['ms']['p50']:.1f}" for each in cameras for key in keys],
        "new pictures per s while `teleop --task --record` runs and the arm moves":
            [f"{each['beside_physics']['new_pictures_per_s'][key]:.1f}" for each in cameras for key in keys],
        "the frames in which the arm moved that hold a new picture":
            [f"{each['beside_physics']['new_while_moving'][key]:.0%}" for each in cameras for key in keys],
    }
    rows += [("loop/task.md", f"| {label} | {' | '.join(values)} |") for label, values in cells.items()]
    rows.append(("loop/task.md", "| the body's joint_state per s meanwhile | " + " | | ".join(
        f"{each['beside_physics']['joint_state_per_s']:.2f}" for each in cameras) + " | |"))
    gym = [saved["gym"]["gym"], saved["gym-mujoco"]["gym"]]

    def times(real_time: float) -> str:
        return f"{real_time:.0f}×" if real_time >= 10 else f"{real_time:.1f}×"

    for label, run in (("no pictures (state), one environment", "state_1_env"), ("no pictures, async vector of 2", "state_2_envs"),
                       ("both cameras 320×240 (all), one environment", "all_1_env"),
                       ("both cameras 320×240, async vector of 2", "all_2_envs")):
        rows.append(("loop/gym.md", f"| {label} | " + " | ".join(
            f"{each['runs'][run]['steps_per_s']:.0f} ({times(each['runs'][run]['times_real_time'])})" for each in gym) + " |"))
    rows.append(("loop/gym.md", "| the dataflow's lockstep, no video | " +
                 " | ".join(f"{each['dataflow_frames_per_s']:.0f} frames/s" for each in gym) + " |"))
    return rows


def test_the_how_tos_benchmark_rows_are_the_saved_results():
    """Where a how-to's table repeats a benchmark's figures, they are the saved result's."""
    for page, row in quoted_rows():
        assert row in page_text(page), f"docs/{page} lacks the saved results' row: {row}"


SUITE_LINES = {  # docs/tests.md: each command's time and how many tests it ran
    "": re.compile(r"python3\.11 bootstrap\.py test .*: [\d a-z]+ here \((\d+) tests\)"),
    "not slow": re.compile(r"\.venv/bin/pytest -m \"not slow\" .*: [\d a-z]+ \((\d+) tests\)"),
}


def test_the_suite_times_in_the_docs_are_from_a_run_of_about_todays_suite():
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
        quoted = SUITE_LINES[marks].search(page_text("tests.md"))
        assert quoted, f"docs/tests.md has no time with its test count for {marks or 'the whole suite'!r}"
        # Within a tenth: a few tests added since the timed run are fine, another era's figure is not.
        assert abs(int(quoted.group(1)) - count) <= count / 10, (quoted.group(0), count)


def test_the_readme_is_a_front_page_with_the_course_steps_and_a_path_to_each_part():
    """At most 300 lines; steps A to D each under a heading of its own, in the course's order; a link to
    each part's page, the SO-101 owner's (record, replay, the leader) among the first."""
    assert len(README.splitlines()) <= 300
    steps = re.findall(r"^#+ Step ([A-D])\b", README, re.MULTILINE)
    assert steps == ["A", "B", "C", "D"]
    linked = re.findall(r"\]\((docs/[^)#]+)", README)
    for page in ("docs/course.md", "docs/bodies/mujoco.md", "docs/bodies/real-arm.md", "docs/loop/record-replay.md",
                 "docs/loop/leader.md", "docs/loop/task.md", "docs/loop/demos.md", "docs/loop/policy.md",
                 "docs/clusters.md"):
        assert page in linked, page
    first_screen = "\n".join(README.splitlines()[:60])
    for page in ("docs/loop/record-replay.md", "docs/loop/leader.md"):
        assert f"]({page}" in first_screen, page


def test_the_readmes_links_reach_their_pages_and_anchors():
    """GitHub shows the README outside the site, so mkdocs does not check its links: this does."""
    from markdown.extensions.toc import slugify

    def anchors(text: str, slug) -> set[str]:
        # A `#` comment in a quoted command is no heading.
        return {slug(heading.replace("`", "")) for heading in re.findall(r"^#+ (.*)$", INDENTED.sub("", text), re.M)}

    def github_slug(heading: str) -> str:
        return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")

    for target in re.findall(r"\]\(([^)]+)\)", README):
        path, _, anchor = target.partition("#")
        if not path:
            assert anchor in anchors(README, github_slug), target
            continue
        assert (ROOT / path).exists(), target
        if anchor:
            assert anchor in anchors((ROOT / path).read_text(encoding="utf-8"), lambda text: slugify(text, "-")), target
