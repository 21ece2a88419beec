"""Headless pictures: `render_rgb` shows the arm, follows its pose, and `so101 snapshot` writes a PNG of it."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest

from so101.cli import main
from so101.simulator import SO101Sim
from tests.image_helpers import arm_pixels, open_png, png_rgb, png_size

SIZE = (160, 120)


def test_render_is_an_rgb_uint8_image_of_the_asked_size(shared_sim):
    rgb = shared_sim.render_rgb(*SIZE)
    assert rgb.dtype == np.uint8
    assert rgb.shape == (SIZE[1], SIZE[0], 3)


def test_the_image_shows_the_arm_and_not_an_empty_scene(make_sim):
    sim = make_sim()
    with_arm = sim.render_rgb(*SIZE)
    assert np.array_equal(with_arm, sim.render_rgb(*SIZE))  # same scene, same pixels: differences below are real
    p.resetBasePositionAndOrientation(sim.robot_id, [50, 50, 0], [0, 0, 0, 1], physicsClientId=sim.client)
    empty = sim.render_rgb(*SIZE)
    assert arm_pixels(empty).sum() == 0
    assert arm_pixels(with_arm).sum() > 0.02 * SIZE[0] * SIZE[1]
    changed = np.abs(with_arm.astype(int) - empty.astype(int)).max(axis=2) > 30
    assert changed.sum() > 0.02 * SIZE[0] * SIZE[1]


def test_the_image_changes_when_the_pose_changes(make_sim):
    sim = make_sim(time_step_s=0.004)
    home = sim.render_rgb(*SIZE)
    sim.set_targets_deg([90.0, -40.0, 40.0, 30.0, 0.0, 30.0])
    sim.step(400)
    moved = sim.render_rgb(*SIZE)
    # The arm's yellow moved: pixels that were arm are floor now, and the other way round.
    assert (arm_pixels(home) & ~arm_pixels(moved)).sum() > 100
    assert (arm_pixels(moved) & ~arm_pixels(home)).sum() > 100


def test_the_snapshot_png_holds_exactly_the_rendered_pixels(tmp_path, monkeypatch):
    rendered = []
    render_rgb = SO101Sim.render_rgb

    def recording_render_rgb(sim, *args, **kwargs):
        rgb = render_rgb(sim, *args, **kwargs)
        rendered.append(rgb.copy())
        return rgb

    monkeypatch.setattr(SO101Sim, "render_rgb", recording_render_rgb)
    out = tmp_path / "arm.png"
    assert main(["snapshot", "--pose", "30", "-20", "20", "10", "0", "--out", str(out), "--width", "48", "--height", "36"]) == 0
    (rgb,) = rendered
    image = open_png(out.read_bytes())
    assert (image.mode, image.size) == ("RGB", (48, 36))
    assert np.array_equal(np.asarray(image), rgb)  # lossless, rows and channels in order


def test_snapshot_writes_a_png_whatever_the_file_is_called(tmp_path):
    out = tmp_path / "arm"  # no suffix for Pillow to guess a format from
    assert main(["snapshot", "--out", str(out), "--width", "32", "--height", "32"]) == 0
    assert png_size(out.read_bytes()) == (32, 32)


def test_snapshot_command_writes_a_png_of_the_arm_in_the_pose(tmp_path, capsys):
    out = tmp_path / "pics" / "arm.png"
    assert main(["snapshot", "--pose", "45", "-30", "30", "20", "0", "--out", str(out), "--width", "200", "--height", "150"]) == 0
    printed = capsys.readouterr().out
    assert f"wrote {out} (200x150)" in printed
    assert "pose reached (deg, joints 0-4 and gripper): 45.0 -30.0 30.0 20.0" in printed
    data = out.read_bytes()
    assert png_size(data) == (200, 150)
    assert arm_pixels(png_rgb(data)).sum() > 0.02 * 200 * 150


def test_snapshot_says_when_the_pose_cannot_be_reached(tmp_path, capsys):
    # Shoulder_lift at 90° from home drives the gripper into the floor; it stops near 38°,
    # and the course's strong motors press the outer joints off their angles too.
    assert main(["snapshot", "--pose", "0", "90", "0", "0", "0", "--out", str(tmp_path / "a.png"), "--width", "32", "--height", "32"]) == 0
    out = capsys.readouterr().out
    assert "note: shoulder_lift" in out and "did not reach the asked angle" in out


@pytest.mark.parametrize(
    "pose, message",
    [
        (["1", "2"], "--pose takes 5 angles (joints 0-4) or 6 (with the gripper), got 2"),
        (["0", "400", "0", "0", "0"], "--pose angle 1 (shoulder_lift) is 400°, outside its range [-100.0°, 100.0°]"),
    ],
)
def test_snapshot_refuses_a_bad_pose_in_one_line(tmp_path, capsys, pose, message):
    out = tmp_path / "never.png"
    assert main(["snapshot", "--pose", *pose, "--out", str(out)]) == 2
    assert capsys.readouterr().err == f"so101 snapshot: {message}\n"
    assert not out.exists()


def test_an_output_path_that_cannot_be_written_gives_one_line_and_exit_1(tmp_path, capsys):
    (tmp_path / "taken").write_text("a file where a folder is asked for")
    assert main(["snapshot", "--out", str(tmp_path / "taken" / "arm.png"), "--width", "32", "--height", "32"]) == 1
    assert capsys.readouterr().err == f"so101 snapshot: cannot use {tmp_path / 'taken'}: File exists\n"


def test_mujoco_draws_the_pose_offscreen(tmp_path, capsys):
    from tests.image_helpers import arm_pixels, png_rgb

    out = tmp_path / "mujoco.png"
    assert main(["snapshot", "--body", "mujoco", "--pose", "90", "0", "0", "0", "0", "--out", str(out),
                 "--width", "160", "--height", "120"]) == 0
    reply = capsys.readouterr().out
    assert reply.startswith(f"wrote {out} (160x120), pose reached (deg, joints 0-4 and gripper): 90.0 ")
    assert arm_pixels(png_rgb(out.read_bytes())).sum() > 0.02 * 160 * 120  # the yellow arm is in the picture
