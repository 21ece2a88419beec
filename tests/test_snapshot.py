"""Headless pictures: `render_rgb` shows the arm, follows its pose, and `so101 snapshot` writes a PNG of it."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest

from so101.cli.main import main
from so101.bodies.pybullet_sim import SO101Sim
from tests.helpers.images import arm_pixels, open_png, png_rgb, png_size

pytestmark = pytest.mark.slow  # renders pictures of the arm: not in the fast subset

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
    from tests.helpers.images import arm_pixels, png_rgb

    out = tmp_path / "mujoco.png"
    assert main(["snapshot", "--body", "mujoco", "--pose", "90", "0", "0", "0", "0", "--out", str(out),
                 "--width", "160", "--height", "120"]) == 0
    reply = capsys.readouterr().out
    assert reply.startswith(f"wrote {out} (160x120), pose reached (deg, joints 0-4 and gripper): 90.0 ")
    assert arm_pixels(png_rgb(out.read_bytes())).sum() > 0.02 * 160 * 120  # the yellow arm is in the picture


# -- --axes: the base frame drawn over the picture ------------------------------------------

AXES_SIZE = (320, 240)
AXIS_ENDS_MM = {"red": (200.0, 0.0, 0.0), "green": (0.0, 200.0, 0.0), "blue": (0.0, 0.0, 200.0)}
HOME_TIP_MM = (391.4, 0.0, 226.5)  # the URDF's gripper_frame_link at home (so101/kinematics.py)


def axis_colour_pixels(rgb: np.ndarray) -> dict[str, np.ndarray]:
    """Where the axes' saturated red, green and blue are; the scene has none of them (floor
    white and pale blue, arm yellow and black, MuJoCo's shadow grey)."""
    red, green, blue = (rgb[:, :, channel].astype(int) for channel in range(3))
    return {
        "red": (red > 180) & (green < 60) & (blue < 60),
        "green": (green > 120) & (red < 60) & (blue < 60),
        "blue": (blue > 180) & (red < 60) & (green < 110),
    }


def near(mask: np.ndarray, pixel, radius: float) -> bool:
    """Whether `mask` has a pixel within `radius` of `pixel` (column, row)."""
    rows, cols = np.nonzero(mask)
    return bool(len(rows)) and float(np.hypot(cols - pixel[0], rows - pixel[1]).min()) <= radius


def snapshot_rgb(tmp_path, *options) -> np.ndarray:
    out = tmp_path / "axes.png"
    width, height = AXES_SIZE
    assert main(["snapshot", *options, "--out", str(out), "--width", str(width), "--height", str(height)]) == 0
    return png_rgb(out.read_bytes())


def test_axes_are_drawn_in_their_colours_along_their_projected_lines(tmp_path):
    from so101.bodies.camera import DEFAULT_CAMERA
    from so101.cli.snapshot import pybullet_projector

    colours = axis_colour_pixels(snapshot_rgb(tmp_path, "--axes"))
    projector = pybullet_projector(DEFAULT_CAMERA, *AXES_SIZE)
    origin = projector.pixels([(0.0, 0.0, 0.0)])[0]
    for colour, end_mm in AXIS_ENDS_MM.items():
        end = projector.pixels([end_mm])[0]
        assert np.hypot(*(end - origin)) > 25  # each axis is a line of some length in this view
        assert near(colours[colour], end, 3), f"{colour} axis does not reach its projected end {end}"
        # The line itself: every point along it is drawn (the labels sit beside it, not on it).
        for fraction in np.linspace(0.1, 0.95, 12):
            point = projector.pixels([np.multiply(end_mm, fraction)])[0]
            assert near(colours[colour], point, 2), f"{colour} axis missing at {fraction:.2f} of its length"
        # No other axis colour out at this end: the colours are not swapped.
        for other in set(AXIS_ENDS_MM) - {colour}:
            assert not near(colours[other], end, 3)


def test_without_axes_the_picture_has_none_of_their_colours(tmp_path):
    rgb = snapshot_rgb(tmp_path, "--pose", "-40", "-20", "10", "30", "0")
    for colour, mask in axis_colour_pixels(rgb).items():
        assert mask.sum() == 0, f"{mask.sum()} {colour} pixels without --axes"
    assert arm_pixels(rgb).sum() > 0.02 * AXES_SIZE[0] * AXES_SIZE[1]


def test_the_axes_are_an_overlay_on_the_rendered_picture(tmp_path):
    plain = snapshot_rgb(tmp_path)
    with_axes = snapshot_rgb(tmp_path, "--axes")
    changed = (plain != with_axes).any(axis=2)
    # Only lines and labels: most of the picture, arm included, is the render's own pixels.
    assert 0.005 * changed.size < changed.sum() < 0.1 * changed.size
    assert (arm_pixels(plain) & ~changed).sum() > 0.9 * arm_pixels(plain).sum()


@pytest.mark.parametrize(
    "camera_options",
    [(), ("--yaw", "-50", "--pitch", "-40", "--distance", "0.8")],
    ids=["default camera", "from the front-left, higher"],
)
@pytest.mark.parametrize("pose", [[0.0] * 6, [-40.0, -20.0, 10.0, 30.0, 0.0, 0.0]], ids=["home", "panned left"])
def test_projected_points_land_on_the_arm_in_the_render(make_sim, camera_options, pose):
    """The origin on the arm's base, and the tip (from FK) where the gripper is: the farthest
    arm pixel from the base is a jaw's end, a little beyond the tip (which lies between the jaws)."""
    from so101.bodies.camera import DEFAULT_CAMERA, Camera
    from so101.cli.snapshot import pybullet_projector

    options = dict(zip(camera_options[::2], map(float, camera_options[1::2])))
    camera = Camera(
        target_xyz_m=DEFAULT_CAMERA.target_xyz_m, fov_deg=DEFAULT_CAMERA.fov_deg,
        yaw_deg=options.get("--yaw", DEFAULT_CAMERA.yaw_deg),
        pitch_deg=options.get("--pitch", DEFAULT_CAMERA.pitch_deg),
        distance_m=options.get("--distance", DEFAULT_CAMERA.distance_m),
    )
    sim = make_sim(time_step_s=0.004)
    sim.set_targets_deg(pose)
    sim.step(600)
    tip_mm = np.array(p.getLinkState(sim.robot_id, 5, physicsClientId=sim.client)[4]) * 1000.0  # gripper_frame_link
    if pose == [0.0] * 6:
        assert np.allclose(tip_mm, HOME_TIP_MM, atol=0.5)
    arm = arm_pixels(sim.render_rgb(*AXES_SIZE, camera))
    origin, tip = pybullet_projector(camera, *AXES_SIZE).pixels([(0.0, 0.0, 0.0), tip_mm])
    rows, cols = np.nonzero(arm)
    # The origin is on the arm, in the lowest part of it (the foot of the base).
    assert near(arm, origin, 2)
    assert rows.max() - origin[1] < 0.15 * (rows.max() - rows.min())
    # The tip is on the arm too, at its far end.
    assert near(arm, tip, 2)
    farthest = np.argmax(np.hypot(cols - origin[0], rows - origin[1]))
    assert np.hypot(cols[farthest] - tip[0], rows[farthest] - tip[1]) < 15


def test_the_axes_use_the_matrices_the_render_used(tmp_path, monkeypatch):
    from so101.cli import snapshot as cmd_snapshot

    used, made = [], []
    get_camera_image, pybullet_projector = p.getCameraImage, cmd_snapshot.pybullet_projector

    def recording_get_camera_image(*args, **kwargs):
        used.append((kwargs["viewMatrix"], kwargs["projectionMatrix"]))
        return get_camera_image(*args, **kwargs)

    def recording_projector(*args, **kwargs):
        made.append(pybullet_projector(*args, **kwargs))
        return made[-1]

    monkeypatch.setattr(p, "getCameraImage", recording_get_camera_image)
    monkeypatch.setattr(cmd_snapshot, "pybullet_projector", recording_projector)
    snapshot_rgb(tmp_path, "--axes", "--yaw", "120", "--pitch", "-50", "--distance", "0.9")
    ((view, projection),), (projector,) = used, made
    column_major = lambda values: np.asarray(values).reshape(4, 4).T  # noqa: E731
    assert np.allclose(projector.matrix, column_major(projection) @ column_major(view), atol=1e-6)
    assert (projector.width, projector.height) == AXES_SIZE


def test_a_line_is_cut_where_it_passes_behind_the_camera():
    from so101.cli.snapshot import Projector

    # A camera at the origin looking along -z (OpenGL's eye frame), 90° field of view, 100x100.
    near_m, far_m = 0.01, 10.0
    projection = np.array([
        [1.0, 0, 0, 0], [0, 1.0, 0, 0],
        [0, 0, -(far_m + near_m) / (far_m - near_m), -2 * far_m * near_m / (far_m - near_m)], [0, 0, -1.0, 0],
    ])
    projector = Projector(projection, 100, 100)
    assert np.allclose(projector.pixels([(0.0, 0.0, -500.0), (500.0, 500.0, -500.0)]), [(50, 50), (100, 0)])
    assert np.isnan(projector.pixels([(0.0, 0.0, 500.0)])).all()
    assert projector.segment((0.0, 0.0, 500.0), (0.0, 0.0, 1000.0)) is None
    start, end = projector.segment((100.0, 0.0, 500.0), (100.0, 0.0, -1000.0))  # from behind to in front
    assert np.allclose(end, (55, 50))
    assert start[0] > 100  # cut at the near plane, far off to the right: not flipped to the left


def test_mujoco_draws_the_axes_where_its_camera_sees_the_base_frame(tmp_path):
    from so101.cli.snapshot import mujoco_projector
    from so101.bodies.mujoco_sim import SO101MuJoCo

    colours = axis_colour_pixels(snapshot_rgb(tmp_path, "--body", "mujoco", "--axes"))
    with SO101MuJoCo(mode="direct", log=lambda message: None) as sim:
        plain = sim.render_rgb(*AXES_SIZE)  # home, unstepped: the angles are exactly 0
        projector = mujoco_projector(sim, *AXES_SIZE)
    assert not any(mask.any() for mask in axis_colour_pixels(plain).values())
    arm = arm_pixels(plain)
    origin, tip = projector.pixels([(0.0, 0.0, 0.0), HOME_TIP_MM])
    assert near(arm, origin, 2) and near(arm, tip, 2)
    for colour, end_mm in AXIS_ENDS_MM.items():
        assert near(colours[colour], projector.pixels([end_mm])[0], 3)
