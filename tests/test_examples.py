"""The course's two stand-alone scripts in examples/, run headless as a student would."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers.dataflow import error_lines

pytestmark = pytest.mark.slow  # runs the course's scripts as processes: not in the fast subset

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def run_example(script: str, *args: str, **env: str) -> subprocess.CompletedProcess:
    environ = {key: value for key, value in os.environ.items() if key not in ("DISPLAY", "SO101_MODE")}
    environ.update(env)
    return subprocess.run(
        [sys.executable, str(EXAMPLES / script), *args], capture_output=True, text=True, env=environ,
        timeout=120, cwd=EXAMPLES.parent,
    )


def test_step_a_prints_the_courses_joint_table(course_printed_table):
    result = run_example("test_so101.py", "--steps", "10", SO101_MODE="direct")
    assert result.returncode == 0, result.stderr
    assert "SO-101 已加载,robot_id = 1" in result.stdout
    assert "关节数量: 7" in result.stdout
    rows = re.findall(r"^  关节 (\d): (\S+)\s+类型: (.+)$", result.stdout, re.MULTILINE)
    assert [(int(index), name, kind) for index, name, kind in rows] == course_printed_table


def test_step_b_reaches_the_courses_angles(course_step_b_deg):
    result = run_example("test_so101_joints.py", SO101_MODE="direct")
    assert result.returncode == 0, result.stderr
    angles = [float(angle) for angle in re.findall(r"^  关节 \d: (-?\d+\.\d)°$", result.stdout, re.MULTILINE)]
    assert angles == pytest.approx(course_step_b_deg, abs=1.0)


@pytest.mark.skipif(sys.platform in ("darwin", "win32"), reason="macOS and Windows always have a window")
def test_without_a_display_auto_runs_headless_and_says_so():
    result = run_example("test_so101.py")  # SO101_MODE unset: auto
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines()[0] == (
        "no display found (DISPLAY is not set or not reachable): running headless in DIRECT mode"
    )
    assert "关节数量: 7" in result.stdout


@pytest.mark.parametrize("script", ["test_so101.py", "test_so101_joints.py"])
def test_a_missing_model_is_one_clear_line(script, tmp_path):
    result = run_example(script, SO101_MODE="direct", SO101_ASSETS_DIR=str(tmp_path / "nowhere"))
    assert result.returncode == 2
    lines = error_lines(result.stderr)
    assert len(lines) == 1
    assert lines[0].startswith(f"{script}: SO-101 model file missing:")
    assert "so101 assets" in lines[0]
