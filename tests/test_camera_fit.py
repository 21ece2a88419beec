"""Camera files and fits: the file's rules, the simulated camera drawn from one (rolled too), the
dataset keeping where each episode's cameras stood, and `so101 cameras --fit` recovering an offset
camera from an episode drawn from it, then drawing its first frame again."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from so101.bodies.camera import TASK_FRONT_CAMERA, WRIST_CAMERA, wrist_placement
from so101.bodies.camera_file import (
    CameraFileError, camera_file_from, default_camera_file, front_file_of, orbit_of, read_camera_file,
)
from so101.camera_pose.fit import Pose, chosen_frames, pose_error
from so101.perception.geometry import view_of

# -- the file ----------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("roll_deg", [0.0, 7.5, -20.0])
def test_a_front_camera_file_is_the_orbiting_camera_it_was_made_from(roll_deg):
    camera = replace(TASK_FRONT_CAMERA, yaw_deg=33.0, pitch_deg=-41.0, roll_deg=roll_deg, fov_deg=52.0)
    back = orbit_of(camera_file_from(json.loads(front_file_of(camera, 640, 480).as_json()), "front"))
    for got, want in zip((back.distance_m, back.yaw_deg, back.pitch_deg, back.roll_deg, back.fov_deg, *back.target_xyz_m),
                         (camera.distance_m, camera.yaw_deg, camera.pitch_deg, camera.roll_deg, camera.fov_deg,
                          *camera.target_xyz_m)):
        assert got == pytest.approx(want, abs=1e-4)  # the file keeps micrometres


def test_the_default_files_are_the_simulators_cameras():
    front = default_camera_file("front")
    eye = view_of(TASK_FRONT_CAMERA, 320, 240).eye
    assert front.position_m == pytest.approx(tuple(eye), abs=1e-6)
    assert front.look_at_m == TASK_FRONT_CAMERA.target_xyz_m and front.fov_deg == 45.0 and front.residual_px is None
    wrist = default_camera_file("wrist").as_dict()
    assert wrist["frame"] == "gripper" and wrist["position_m"] == list(WRIST_CAMERA.eye_m)
    assert wrist_placement(WRIST_CAMERA)[1] == pytest.approx((0.976244, -0.216672, 0.0, 0.0), abs=1e-6)


@pytest.mark.parametrize("fields, said", [
    ("[1, 2]", "a camera file is a JSON object"),
    ('{"camera": "back"}', "`camera` must be one of front, wrist, got 'back'"),
    ('{"camera": "wrist", "position_m": [0, 0, 0]}', "this file is the wrist camera's, not the front camera's"),
    ('{"camera": "front", "frame": "gripper"}', "the front camera's vectors are in the base frame, not 'gripper'"),
    ('{"camera": "front", "position_m": [1, 2]}', "`position_m` must be three numbers"),
    ('{"camera": "front", "position_m": [0, 0, 1], "look_at_m": [0, 0, 1], "up": [0, 0, 1], "fov_deg": 45}',
     "`look_at_m` must be at least 1 mm from `position_m`"),
    ('{"camera": "front", "position_m": [0.4, 0, 0.5], "look_at_m": [0, 0, 0], "up": [-0.4, 0, -0.5], "fov_deg": 45}',
     "`up` must not be zero nor along the line of sight"),
    ('{"camera": "front", "position_m": [0, 0, 0.5], "look_at_m": [0, 0, 0], "up": [1, 0, 0], "fov_deg": 45}',
     "the front camera looks straight up or down"),
    ('{"camera": "front", "position_m": [0.4, 0, 0.5], "look_at_m": [0, 0, 0], "up": [0, 0, 1], "fov_deg": 200}',
     "`fov_deg` (the vertical field of view) must be a number of degrees from 1 to 170, got 200"),
    ('{"camera": "front", "position_m": [0.4, 0, 0.5], "look_at_m": [0, 0, 0], "up": [0, 0, 1], "fov_deg": 45, '
     '"width": 0}', "`width` must be a whole number of pixels from 1 to 8192, got 0"),
    ("not json", "not a camera file: not JSON"),
])
def test_a_file_that_is_not_a_camera_file_is_refused_in_one_line(tmp_path, fields, said):
    path = tmp_path / "camera.json"
    path.write_text(fields, encoding="utf-8")
    with pytest.raises(CameraFileError) as refused:
        read_camera_file(path, "front")
    assert said in str(refused.value) and str(refused.value).startswith(str(path)) and "\n" not in str(refused.value)


def test_a_pose_moved_and_moved_back_is_where_it_was_and_its_error_says_how_far():
    start = Pose.of(default_camera_file("front"))
    moved = start.moved([0.03, -0.01, 0.02, 0.05, -0.1, 0.02, 3.0])
    error_m, error_deg, error_fov = pose_error(moved.camera_file(320, 240), start.camera_file(320, 240))
    assert error_m == pytest.approx(math.sqrt(0.03 ** 2 + 0.01 ** 2 + 0.02 ** 2), abs=1e-6)
    assert error_deg == pytest.approx(math.degrees(np.linalg.norm([0.05, -0.1, 0.02])), abs=1e-4)
    assert chosen_frames(5, 16) == [0, 1, 2, 3, 4] and chosen_frames(100, 4) == [0, 33, 66, 99]


# -- drawn from a file ---------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_the_renderer_draws_a_rolled_camera_where_its_geometry_projects():
    """The cube's pixels, drawn by MuJoCo from a camera turned about its line of sight, are where the
    camera's pinhole model (so101.perception.geometry) puts the cube's centre."""
    from so101.bodies.task_cameras import TaskCameras
    from so101.robot import HOME_POSE_DEG
    from so101.tasks import CUBE_TO_BOX

    with TaskCameras(CUBE_TO_BOX, log=lambda line: None) as cameras:
        model = cameras._model
        cameras.draw(HOME_POSE_DEG, [], 320, 240)
        cube = model.model.geom("cube").id
        for roll_deg, fov_deg in ((0.0, 45.0), (12.0, 40.0), (-15.0, 50.0)):
            camera = replace(TASK_FRONT_CAMERA, roll_deg=roll_deg, fov_deg=fov_deg)
            model.model.vis.global_.fovy = fov_deg
            rows, columns = np.nonzero(model.render_geoms(320, 240, camera) == cube)
            projected = view_of(camera, 320, 240).project(model.data.geom_xpos[cube])[0]
            assert np.hypot(columns.mean() + 0.5 - projected[0], rows.mean() + 0.5 - projected[1]) < 0.5, roll_deg


# -- the fit -------------------------------------------------------------------------------------------------------


def test_pictures_where_nothing_moves_say_the_camera_shows_no_arm():
    from so101.camera_pose.fit import CameraFitError, fit_camera
    from so101.robot import HOME_POSE_DEG

    floor = np.full((4, 120, 160, 3), 200, dtype=np.uint8)
    with pytest.raises(CameraFitError, match="the pictures show no arm where it moves: is the camera on the arm"):
        fit_camera(list(floor), [HOME_POSE_DEG] * 4, default_camera_file("front", 160, 120))


def test_a_fit_that_fails_leaves_the_file_there_and_says_why_in_one_line(tmp_path, monkeypatch, capsys):
    from so101.cli.main import main
    from so101.camera_pose import fit as camera_fit

    kept = tmp_path / "front.json"
    kept.write_text("mine\n", encoding="utf-8")

    def refused(*args, **kwargs):
        raise camera_fit.CameraFitError("the fit did not converge: the arm's outline lies 3.1 px from the pictures'")

    monkeypatch.setattr(camera_fit, "fit_from_dataset", refused)
    assert main(["cameras", "--fit", "front", "--from", str(tmp_path), "-o", str(kept)]) == 2
    assert main(["cameras", "--fit", "front"]) == 2
    assert main(["cameras", "--fit", "front", "--from", str(tmp_path), "--near", str(kept)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == ["so101 cameras: the fit did not converge: the arm's outline lies 3.1 px from the pictures'",
                   "so101 cameras: --fit NAME needs --from DATASET: the episode whose pictures and joint states are fitted",
                   f"so101 cameras: --near {kept}: not a camera file: not JSON (Expecting value, line 1)"]
    assert kept.read_text(encoding="utf-8") == "mine\n"
    # An option of another mode, or a negative episode: one line each, nothing done.
    for argv, said in ((["--fit", "front", "--from", str(tmp_path), "--port", "/dev/ttyACM0"], "--port goes with --align NAME"),
                       (["--default", "front", "--from", str(tmp_path)], "--from goes with --fit NAME or --backdrop NAME"),
                       (["--default", "front", "--episode", "2"], "--episode goes with --fit NAME or --backdrop NAME"),
                       (["--fit", "front", "--max-holes", "0.1"], "--max-holes goes with --backdrop NAME"),
                       (["--fit", "front", "--size", "64x48"], "--size goes with --default NAME"),
                       (["--port", "/dev/ttyACM0"], "--port goes with --align NAME")):
        assert main(["cameras", *argv]) == 2
        assert capsys.readouterr().err == f"so101 cameras: {said}\n", argv
    with pytest.raises(SystemExit):
        main(["cameras", "--fit", "front", "--from", str(tmp_path), "--episode", "-1"])
    assert "--episode: " in capsys.readouterr().err


@pytest.mark.dataflow
def test_the_fit_recovers_the_camera_an_episode_was_drawn_from_and_redraws_its_first_frame(tmp_path):
    """An episode drawn from the front camera moved 4.2 cm, turned 8° and 4° wider, with varied looks on top:
    the fit from the default camera lands within 5 mm, 1° and 1° of field of view of where the episode's
    camera stood (its scenario's cameras entry), and that file draws the first frame again within 3 of
    255 of the frame as drawn. tools/camera_fit_offsets.py runs more offsets."""
    from so101.bodies.task_cameras import TaskCameras
    from so101.dataset.features import ENVIRONMENT_KEY, STATE_KEY, from_lerobot
    from so101.dataset.reader import Dataset
    from so101.tasks import CUBE_TO_BOX

    start = Pose.of(default_camera_file("front"))
    moved = Pose(start.eye + np.array([0.03, -0.02, 0.02]), start.axes @ _turn(0.08, -0.1, 0.04), 49.0)
    pose_file, root, fitted = tmp_path / "moved.json", tmp_path / "demos", tmp_path / "fitted.json"
    pose_file.write_text(moved.camera_file(320, 240).as_json(), encoding="utf-8")
    so101 = [str(Path(sys.executable).parent / "so101")]
    made = subprocess.run([*so101, "demos", str(root), "--task", "cube_to_box", "--episodes", "1", "--seed", "7",
                           "--looks", "varied", "--camera-pose", f"front={pose_file}"], capture_output=True, text=True)
    assert made.returncode == 0, made.stdout + made.stderr
    fit = subprocess.run([*so101, "cameras", "--fit", "front", "--from", str(root), "-o", str(fitted)],
                         capture_output=True, text=True)
    assert fit.returncode == 0, fit.stdout + fit.stderr
    assert fit.stdout == "" and fit.stderr.splitlines()[-1] == f"wrote {fitted}"
    info = json.loads((root / "meta" / "info.json").read_text(encoding="utf-8"))
    truth = camera_file_from(info["so101_episode_scenarios"]["0"]["cameras"]["front"], "front")
    refit = read_camera_file(fitted, "front")
    assert pose_error(default_camera_file("front"), truth)[0] > 0.04  # the start is far off
    error_m, error_deg, error_fov = pose_error(refit, truth)
    assert error_m < 0.005 and error_deg < 1.0 and error_fov < 1.0, (error_m, error_deg, error_fov)
    assert 0 < refit.residual_px < 0.8 and (refit.width, refit.height) == (320, 240)

    dataset = Dataset.open(root)
    columns = dataset.episode_frames(0)
    first = next(iter(dataset.episode_images(0, "observation.images.front")))
    with TaskCameras(CUBE_TO_BOX, log=lambda line: None, looks="varied") as cameras:
        cameras.show_seed(7)
        drawn = {name: cameras.draw(from_lerobot(columns[STATE_KEY][0]), columns[ENVIRONMENT_KEY][0], 320, 240,
                                    wrist=False, front=orbit_of(camera))[0] for name, camera in (("refit", refit),
                                                                                               ("truth", truth))}
    # The first frame as drawn (the video's copy is about 2 of 255 away from it: compression, colour rounding).
    assert np.abs(drawn["truth"].astype(int) - first).mean() < 2.5
    assert np.abs(drawn["refit"].astype(int) - drawn["truth"]).mean() < 3.0


def _turn(*turn_rad: float) -> np.ndarray:
    from so101.camera_pose.fit import _rotation

    return _rotation(np.array(turn_rad))
