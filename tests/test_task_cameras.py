"""One renderer for every simulated body (so101.bodies.task_cameras): the same state, the same picture,
whichever body simulated it."""

from __future__ import annotations

import numpy as np
import pytest

from so101.bodies.registry import BODIES
from so101.tasks import CUBE_TO_BOX

pytestmark = pytest.mark.slow

SIZE = (160, 120)


@pytest.fixture(scope="module", params=["fixed", "varied"])
def cameras(request):
    from so101.bodies.task_cameras import TaskCameras

    with TaskCameras(CUBE_TO_BOX, log=lambda line: None, looks=request.param) as made:
        yield made


def first_frame(body_name: str, seed: int, cameras) -> tuple[np.ndarray, np.ndarray]:
    """The pictures of an episode's first frame, as a body running `seed` publishes its state (and, with
    varied looks, in that seed's looks, as a lockstep body shows them at a reset)."""
    with BODIES[body_name].body_class()(mode="direct", renders=False, log=lambda line: None, task=CUBE_TO_BOX,
                                        seed=seed) as body:
        body.step()
        cameras.show_seed(seed)
        front, wrist = cameras.draw(body.joint_angles_deg(), body.scene.object_state(), *SIZE)
    assert front.shape == wrist.shape == (SIZE[1], SIZE[0], 3) and front.dtype == np.uint8
    return front, wrist


def mean_difference(first: np.ndarray, second: np.ndarray) -> float:
    return float(np.mean(np.abs(first.astype(np.int16) - second.astype(np.int16))))


@pytest.mark.parametrize("seed", [0, 7, 12])
def test_an_episodes_first_frame_looks_the_same_on_both_simulators(cameras, seed):
    pybullet, mujoco = first_frame("pybullet", seed, cameras), first_frame("mujoco", seed, cameras)
    for pybullet_picture, mujoco_picture in zip(pybullet, mujoco):
        assert mean_difference(pybullet_picture, mujoco_picture) <= 3.0
    # Not the same picture whatever the state: the next seed's cube lies elsewhere in the front picture
    # (the wrist camera, at home, looks past the floor's cube).
    elsewhere = first_frame("mujoco", seed + 1, cameras)
    assert mean_difference(mujoco[0], elsewhere[0]) > 0.2


def test_the_pictures_follow_the_pose_and_the_objects(cameras):
    from so101.robot import HOME_POSE_DEG

    objects = [0.2, -0.05, 0.0125, 0.0, 0.0, 0.0, 1.0, 0.16, 0.19, 0.0]
    home_front, home_wrist = cameras.draw(HOME_POSE_DEG, objects, *SIZE)
    turned_front, turned_wrist = cameras.draw([40.0, -30.0, 30.0, 60.0, 0.0, 30.0], objects, *SIZE)
    assert mean_difference(home_front, turned_front) > 2.0 and mean_difference(home_wrist, turned_wrist) > 2.0
    again_front, _ = cameras.draw(HOME_POSE_DEG, objects, *SIZE)
    assert mean_difference(again_front, home_front) < 0.01  # drawn from the state alone, nothing left over


def test_without_a_task_there_is_no_wrist_picture():
    from so101.bodies.task_cameras import TaskCameras
    from so101.robot import HOME_POSE_DEG

    with TaskCameras(None, log=lambda line: None) as arm_alone:
        front, wrist = arm_alone.draw(HOME_POSE_DEG, [], *SIZE)
    assert front.shape == (SIZE[1], SIZE[0], 3) and wrist is None


def test_a_repeated_picture_decodes_the_same_and_a_half_degree_move_does_not(cameras, tmp_path):
    """What `so101 bench --cameras` counts as a new picture (bench/record_bench.py's NEW_PICTURE_LEVELS):
    a repeat decodes the same to the level; the arm moved half a degree, by well over the threshold."""
    import av

    from bench.record_bench import NEW_PICTURE_LEVELS
    from so101.dataset.video import StreamingEncoder, picture_changes

    objects = [0.2, -0.05, 0.0125, 0.0, 0.0, 0.0, 1.0, 0.16, 0.19, 0.0]
    drawn = [cameras.draw([0.5 * step, -0.4 * step, 0.3 * step, 10.0, 1.0 * step, 30.0], objects, *SIZE)
             for step in range(10)]
    for camera in (0, 1):
        path = tmp_path / f"camera{camera}.mp4"
        encoder = StreamingEncoder(path, 30, *SIZE)
        for pictures in drawn:
            encoder.add(pictures[camera])
            encoder.add(pictures[camera])  # the camera fell behind: the recorder repeats its last picture
        encoder.finish()
        with av.open(str(path)) as video:
            decoded = [frame.to_ndarray(format="rgb24") for frame in video.decode(video=0)]
        assert picture_changes(decoded, NEW_PICTURE_LEVELS) == [False, False] + [True, False] * 9


def test_varied_looks_differ_by_seed_and_come_back_with_it():
    from so101.bodies.task_cameras import TaskCameras
    from so101.robot import HOME_POSE_DEG

    objects = [0.2, -0.05, 0.0125, 0.0, 0.0, 0.0, 1.0, 0.16, 0.19, 0.0]
    with TaskCameras(CUBE_TO_BOX, log=lambda line: None, looks="varied") as varied, \
            TaskCameras(CUBE_TO_BOX, log=lambda line: None) as fixed:
        fixed.show_seed(3)  # fixed looks: whatever the seed, as always
        plain = fixed.draw(HOME_POSE_DEG, objects, *SIZE)
        pictures = {}
        for seed in (3, 4, 3):
            varied.show_seed(seed)
            pictures.setdefault(seed, []).append(varied.draw(HOME_POSE_DEG, objects, *SIZE))
    (first, again), (other,) = pictures[3], pictures[4]
    # The same seed, the same looks (a first picture may differ from later ones in a pixel's last bit).
    assert all(mean_difference(a, b) < 0.01 for a, b in zip(first, again))
    for camera in (0, 1):
        assert mean_difference(first[camera], other[camera]) > 3.0
        assert mean_difference(first[camera], plain[camera]) > 3.0



@pytest.mark.parametrize("seed", [3, 1004])
def test_the_eyes_geometry_puts_the_cube_where_the_renderer_draws_it(cameras, seed):
    """so101.perception.geometry's camera is the renderer's: the cube's pixels (the picture with it, less the
    picture without it) centre on its centre's projection, in either looks (the camera moved and turned)."""
    from so101.perception.geometry import view_of

    cameras.show_seed(seed)
    layout = CUBE_TO_BOX.layout(seed)
    state = [*layout.cube_xyz_m, *layout.cube_quat_xyzw(), *layout.box_xyz_m]
    angles = (0.0, -100.0, 90.0, 70.0, 0.0, 0.0)  # the jaws above the floor near the base, clear of the sector
    with_cube, _ = cameras.draw(angles, state, 320, 240, wrist=False)
    without, _ = cameras.draw(angles, [5.0, 5.0, *state[2:]], 320, 240, wrist=False)
    rows, columns = np.nonzero(np.abs(with_cube.astype(int) - without.astype(int)).sum(axis=2) > 30)
    assert len(rows) > 30
    u, v = view_of(cameras.front_camera(), 320, 240).project([layout.cube_xyz_m])[0]
    # The centroid of what is seen of the cube: its top face pulls it up (v) by a pixel or two.
    assert abs(columns.mean() + 0.5 - u) < 1.5 and -3.0 < rows.mean() + 0.5 - v < 1.0, (columns.mean(), rows.mean(), u, v)
