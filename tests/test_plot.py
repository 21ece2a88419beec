"""`so101 plot-step`: the exercise-2 figure and its table, run as a user runs it."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from so101.cli.main import main
from tests.helpers.images import png_size

pytestmark = pytest.mark.slow  # runs so101 plot-step: not in the fast subset

ROW = re.compile(r"^\s+(?P<damping>[\d.]+)\s+(?P<overshoot>[\d.]+) %\s+(?P<settling>[\d.]+ s|never)\s+(?P<error>[+-][\d.]+)°$")


def run_plot_step(*options: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "so101.cli", "plot-step", *options], capture_output=True, text=True, timeout=300,
    )


def table(stdout: str) -> dict[float, dict[str, str]]:
    rows = {}
    for line in stdout.splitlines():
        match = ROW.match(line)
        if match:
            rows[float(match["damping"])] = match.groupdict()
    return rows


def test_servo_plot_shows_overshoot_falling_with_damping(tmp_path):
    out = tmp_path / "figs" / "servo.png"
    result = run_plot_step("--mode", "servo", "--damping", "0.2", "0.7", "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert "joint 0 (shoulder_pan) 0° -> 90°, servo mode" in result.stdout
    rows = table(result.stdout)
    assert set(rows) == {0.2, 0.7}
    assert float(rows[0.2]["overshoot"]) > 10.0
    assert float(rows[0.7]["overshoot"]) < 5.0
    assert rows[0.7]["settling"] != "never"
    assert abs(float(rows[0.7]["error"])) < 1.0
    assert "largest torque sent: 3.35 N·m" in result.stdout
    assert f"wrote {out}" in result.stdout
    # 8 x 4.8 inches at 100 dpi; a figure with lines and a legend is tens of kB.
    assert png_size(out.read_bytes()) == (800, 480)
    assert 20_000 < out.stat().st_size < 200_000


def test_position_plot_shows_no_overshoot_with_or_without_link_damping(tmp_path):
    out = tmp_path / "position.png"
    result = run_plot_step("--mode", "position", "--duration", "1", "--out", str(out))
    assert result.returncode == 0, result.stderr
    rows = table(result.stdout)
    assert set(rows) == {0.0, 0.2}
    assert [rows[value]["overshoot"] for value in (0.0, 0.2)] == ["0.0", "0.0"]
    assert rows[0.0]["settling"] == rows[0.2]["settling"]  # the course's link damping changes nothing here
    assert out.stat().st_size > 20_000


def test_a_target_outside_the_joint_range_is_refused(tmp_path, capsys):
    assert main(["plot-step", "--target", "300", "--out", str(tmp_path / "x.png")]) == 2
    assert capsys.readouterr().err == (
        "so101 plot-step: --target 300° is outside joint 0 (shoulder_pan)'s range [-110.0°, 110.0°]\n"
    )


def test_mujoco_plot_shows_the_courses_exercise_joint_damping_stops_the_swing(tmp_path):
    out = tmp_path / "mujoco.png"
    result = run_plot_step("--body", "mujoco", "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert "MuJoCo: the MJCF's position servos" in result.stdout
    rows = table(result.stdout)
    assert set(rows) == {0.6, 0.3, 0.0}  # the MJCF's damping first, then less, then none
    assert float(rows[0.0]["overshoot"]) > float(rows[0.3]["overshoot"]) > float(rows[0.6]["overshoot"])
    assert rows[0.6]["settling"] != "never" and abs(float(rows[0.6]["error"])) < 1.0
    assert rows[0.0]["settling"] == "never"  # it swings past the end of the run
    assert "with joint damping 0 the joint is still swinging at the end" in result.stdout
    assert png_size(out.read_bytes()) == (800, 480)
