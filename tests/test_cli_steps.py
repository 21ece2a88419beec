"""`so101 inspect` and `so101 joints` (course steps A and B), run as a user runs them."""

from __future__ import annotations

import re
import sys

import pytest

from tests.helpers.dataflow import error_lines, run_so101

pytestmark = pytest.mark.slow  # runs so101 inspect and so101 joints as processes: not in the fast subset

def table_rows(stdout: str, word: str, type_word: str) -> list[tuple[int, str, str]]:
    pattern = re.compile(rf"^\s+{word} (\d+): (\S+)\s+{type_word}: (.+?)(?:\s+\[.*\])?$")
    return [
        (int(match[1]), match[2], match[3])
        for match in map(pattern.match, stdout.splitlines())
        if match
    ]


def test_inspect_prints_the_courses_table(course_printed_table):
    result = run_so101("inspect", "--mode", "direct", "--steps", "1")
    assert result.returncode == 0, result.stderr
    assert "SO-101 已加载,robot_id = 1" in result.stdout
    assert "关节数量: 7" in result.stdout
    assert table_rows(result.stdout, "关节", "类型") == course_printed_table
    assert "Traceback" not in result.stderr


def test_inspect_in_english_with_the_limits_in_degrees(course_joint_table):
    result = run_so101("inspect", "--mode", "direct", "--steps", "1", "--lang", "en")
    assert result.returncode == 0, result.stderr
    assert "joints: 7" in result.stdout
    assert table_rows(result.stdout, "joint", "type") == course_joint_table
    shoulder_pan = next(line for line in result.stdout.splitlines() if "shoulder_pan" in line)
    assert re.search(r"\[\s*-110\.0°,\s+110\.0°\]", shoulder_pan), shoulder_pan


def test_language_comes_from_so101_lang():
    result = run_so101("inspect", "--mode", "direct", "--steps", "1", SO101_LANG="en")
    assert result.returncode == 0, result.stderr
    assert "joints: 7" in result.stdout


def test_a_bad_so101_lang_is_a_one_line_error():
    result = run_so101("inspect", "--mode", "direct", "--steps", "1", SO101_LANG="fr")
    assert result.returncode == 2
    assert "argument --lang: unknown language 'fr' (from --lang or $SO101_LANG); use zh or en" in result.stderr
    assert "Traceback" not in result.stderr


def reached_angles(stdout: str, word: str) -> list[float]:
    return [float(match[1]) for match in re.finditer(rf"^\s+{word} \d+: (-?\d+\.\d)°$", stdout, re.MULTILINE)]


def test_joints_reaches_the_courses_targets(course_step_b_deg):
    result = run_so101("joints", "--mode", "direct", "--steps", "1")
    assert result.returncode == 0, result.stderr
    assert "当前关节角度:" in result.stdout
    angles = reached_angles(result.stdout, "关节")
    assert len(angles) == 5
    assert angles == pytest.approx(course_step_b_deg, abs=1.0)


def test_joints_takes_other_targets():
    targets_rad = ["0", "-0.3", "0", "0.2", "0"]
    result = run_so101("joints", "--mode", "direct", "--steps", "1", "--lang", "en", "--targets", *targets_rad)
    assert result.returncode == 0, result.stderr
    assert reached_angles(result.stdout, "joint") == pytest.approx([0.0, -17.19, 0.0, 11.46, 0.0], abs=1.0)


@pytest.mark.skipif(sys.platform in ("darwin", "win32"), reason="macOS and Windows always have a window")
def test_auto_mode_without_display_runs_headless_with_a_notice():
    result = run_so101("inspect", "--steps", "1")  # run_so101 runs it without DISPLAY
    assert result.returncode == 0, result.stderr
    assert "running headless in DIRECT mode" in result.stdout + result.stderr
    assert "关节数量: 7" in result.stdout


@pytest.mark.skipif(sys.platform in ("darwin", "win32"), reason="macOS and Windows always have a window")
def test_gui_without_display_is_a_one_line_error():
    result = run_so101("inspect", "--mode", "gui", "--steps", "1")
    assert result.returncode == 2
    lines = error_lines(result.stderr)
    assert len(lines) == 1
    assert lines[0].startswith("so101 inspect: GUI mode needs a display")


def test_help_lists_the_subcommands():
    result = run_so101("--help")
    assert result.returncode == 0
    for name in ("assets", "inspect", "joints"):
        assert re.search(rf"^\s+{name}\s+\S", result.stdout, re.MULTILINE), name


def test_an_unknown_mode_is_refused_with_the_choices():
    result = run_so101("inspect", "--mode", "window")
    assert result.returncode == 2
    assert "invalid choice: 'window'" in result.stderr
    assert "Traceback" not in result.stderr
