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

from so101.bodies.camera import TASK_FRONT_CAMERA, WRIST_CAMERA
from so101.bodies.camera_file import (
    CameraFileError, camera_file_from, default_camera_file, front_file_of, orbit_of, read_camera_file, wrist_placement,
)
from so101.perception.camera_fit import Pose, chosen_frames, pose_error
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
