"""The cameras' meshes (so101.bodies.camera_meshes): the clustering, the derived files, and that a
task's cameras draw them and see what the full meshes show."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from so101 import assets
from so101.bodies import camera_meshes
from so101.bodies.camera import DEFAULT_CAMERA, WRIST_CAMERA
from so101.bodies.registry import BODIES
from so101.bodies.stl import stl_bytes, stl_points
from so101.tasks import task_named
from tests.helpers.dataflow import copy_model, corrupt

CELL = camera_meshes.CELL_M


def normals(corners: np.ndarray) -> np.ndarray:
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return normal / np.linalg.norm(normal, axis=1, keepdims=True)


def test_corners_in_one_cell_become_their_mean_and_triangles_that_lose_an_edge_go():
    big = [[0.0, 0.0, 0.0], [10 * CELL, 0.0, 0.0], [0.0, 10 * CELL, 0.0]]
    # Shares the big one's first two cells: its corners there move to the cells' means.
    beside = [[0.2 * CELL, 0.2 * CELL, 0.0], [10.4 * CELL, 0.4 * CELL, 0.0], [10 * CELL, 10 * CELL, 0.0]]
    within_a_cell = [[0.5 * CELL, 0.5 * CELL, 0.0], [0.6 * CELL, 0.5 * CELL, 0.0], [0.5 * CELL, 0.6 * CELL, 0.0]]
    sliver = [[3 * CELL, 3 * CELL, 0.0], [3.1 * CELL, 3.1 * CELL, 0.0], [8 * CELL, 2 * CELL, 0.0]]
    kept = camera_meshes.cluster_vertices([big, beside, within_a_cell, sliver])
    first_cell_mean = np.mean([big[0], beside[0]] + within_a_cell, axis=0)
    second_cell_mean = np.mean([big[1], beside[1]], axis=0)
    assert kept.dtype == np.float32 and kept.shape == (2, 3, 3)
    np.testing.assert_allclose(kept[0], [first_cell_mean, second_cell_mean, big[2]], atol=1e-9)
    np.testing.assert_allclose(kept[1], [first_cell_mean, second_cell_mean, beside[2]], atol=1e-9)


def test_a_decimated_mesh_faces_the_way_the_model_does(model_dir):
    # The jaw, whose faces a wrist picture shows closest: the triangles that stay keep their side out.
    corners = stl_points(model_dir / "assets" / "moving_jaw_so101_v1.stl").reshape(-1, 3, 3).astype(np.float64)
    kept = camera_meshes.cluster_vertices(corners).astype(np.float64)
    assert len(kept) < len(corners) / 3
    # Each kept triangle's normal against the model's triangles whose centroid is nearest its own.
    centroids = corners.mean(axis=1)
    nearest = [np.argmin(np.sum((centroids - centre) ** 2, axis=1)) for centre in kept.mean(axis=1)[::50]]
    agreement = np.sum(normals(kept[::50]) * normals(corners[nearest]), axis=1)
    assert np.mean(agreement > 0) > 0.9


def test_an_stl_holds_each_triangle_with_its_unit_normal(tmp_path):
    triangles = np.float32([[[0, 0, 0], [2, 0, 0], [0, 3, 0]], [[0, 0, 0], [0, 0, 0], [0, 0, 0]]])
    path = tmp_path / "two.stl"
    path.write_bytes(stl_bytes(triangles, "two"))
    assert stl_points(path).tolist() == triangles.reshape(-1, 3).tolist()
    stored = np.frombuffer(path.read_bytes(), "<f4", 3, 84).tolist()
    assert stored == [0.0, 0.0, 1.0]  # and the triangle without area: zeros, not NaN
    assert np.frombuffer(path.read_bytes(), "<f4", 3, 84 + 50).tolist() == [0.0, 0.0, 0.0]


def test_the_cameras_urdf_draws_the_decimated_meshes_and_collides_the_same_files(tmp_path):
    urdf = ('<link name="a"><visual><geometry><mesh filename="../assets/jaw.stl"/></geometry></visual>'
            '<collision><geometry><mesh filename="jaw.stl"/></geometry></collision></link>')
    meshes = {"jaw.stl": tmp_path / "camera_meshes" / "jaw.stl"}
    text = camera_meshes.urdf_for_cameras(urdf, tmp_path / "hulls", meshes)
    assert text == (f'<link name="a"><visual><geometry><mesh filename="{meshes["jaw.stl"]}"/></geometry></visual>'
                    f'<collision><geometry><mesh filename="{tmp_path / "hulls" / "jaw.stl"}"/></geometry></collision></link>')


def mesh_names() -> list[str]:
    return sorted(Path(relpath).name for relpath in assets.manifest() if relpath.endswith(".stl"))


@pytest.fixture(scope="module")
def derived_copy(tmp_path_factory) -> Path:
    """A copy of the model with the cameras' meshes derived from scratch, once for this module."""
    copy = copy_model(tmp_path_factory.mktemp("derived") / "SO101")
    assert camera_meshes.meshes_problem(copy) == "missing"
    derived = camera_meshes.derive_camera_meshes(copy)
    assert derived.model_triangles == 322_564 and derived.triangles < derived.model_triangles / 5
    return copy


def test_the_meshes_are_derived_from_scratch_with_their_manifest(derived_copy, model_dir):
    folder = derived_copy / camera_meshes.CAMERA_MESHES_DIR_NAME
    assert camera_meshes.meshes_problem(derived_copy) is None
    assert sorted(path.name for path in folder.iterdir()) == sorted(mesh_names() + [camera_meshes.MANIFEST_NAME])
    first_line = (folder / camera_meshes.MANIFEST_NAME).read_text().splitlines()[0]
    assert first_line == f"# vertex clustering 0.001 m; model {assets.manifest_digest()}"
    # Whoever derives them gets the same bytes: the checkout's own (its simulators' first start) and these.
    ours = camera_meshes.camera_meshes(model_dir, log=lambda line: None)
    assert ours is not None
    assert {name: path.read_bytes() for name, path in ours.items()} == {
        name: (folder / name).read_bytes() for name in mesh_names()
    }


def remove_a_mesh(folder: Path, monkeypatch) -> None:
    (folder / "upper_arm_so101_v1.stl").unlink()


def corrupt_a_mesh(folder: Path, monkeypatch) -> None:
    corrupt(folder / "upper_arm_so101_v1.stl")


def another_grid(folder: Path, monkeypatch) -> None:
    monkeypatch.setattr(camera_meshes, "CELL_M", 0.002)


UNUSABLE = {
    "no manifest": (lambda folder, monkeypatch: (folder / camera_meshes.MANIFEST_NAME).unlink(), "missing"),
    "a mesh removed": (remove_a_mesh, "missing"),
    "a mesh corrupt": (corrupt_a_mesh, "corrupt"),
    "another grid": (another_grid, "derived from another model or grid"),
}


@pytest.mark.parametrize("make, problem", UNUSABLE.values(), ids=UNUSABLE.keys())
def test_missing_corrupt_or_stale_meshes_are_not_used(derived_copy, tmp_path, monkeypatch, make, problem):
    copy = tmp_path / "SO101"
    shutil.copytree(derived_copy, copy)
    make(copy / camera_meshes.CAMERA_MESHES_DIR_NAME, monkeypatch)
    assert camera_meshes.meshes_problem(copy) == problem


def pybullet_visual_files(sim) -> set[Path]:
    import pybullet as p

    return {Path(row[4].decode()).resolve() for row in p.getVisualShapeData(sim.robot_id, physicsClientId=sim.client)}


@pytest.mark.slow
def test_a_model_without_them_gets_them_at_a_light_cameras_start_and_only_the_visual_meshes_change(model_copy):
    from so101.bodies.pybullet_sim import SO101Sim

    folder = model_copy / camera_meshes.CAMERA_MESHES_DIR_NAME
    told: list[str] = []
    with SO101Sim(mode="direct", assets_dir=model_copy, log=told.append) as sim:
        assert pybullet_visual_files(sim) == {model_copy / "assets" / name for name in mesh_names()}
        assert not folder.exists()  # pictures without light_pictures: the model's meshes, as the course draws them
    with SO101Sim(mode="direct", assets_dir=model_copy, log=told.append, light_pictures=True) as light:
        assert pybullet_visual_files(light) == {folder / name for name in mesh_names()}
    assert told[-1].startswith("Camera meshes derived from the model's meshes (")
    assert told[-1].endswith(f" of their 322,564 triangles): {folder}")


@pytest.mark.slow
def test_where_they_cannot_be_written_the_cameras_draw_the_full_meshes(model_copy):
    from so101.bodies.pybullet_sim import SO101Sim

    (model_copy / camera_meshes.CAMERA_MESHES_DIR_NAME).write_text("a file where the folder would go")
    told: list[str] = []
    with SO101Sim(mode="direct", assets_dir=model_copy, log=told.append, light_pictures=True) as sim:
        assert pybullet_visual_files(sim) == {model_copy / "assets" / name for name in mesh_names()}
    assert told[-1] == (
        f"Camera meshes not derived: cannot write {model_copy / camera_meshes.CAMERA_MESHES_DIR_NAME} (File exists); "
        "the cameras draw the full meshes instead (the same pictures, slower)"
    )


@pytest.mark.slow
@pytest.mark.parametrize("body", ["pybullet", "mujoco"])
def test_the_decimated_meshes_show_what_the_full_ones_show(body, monkeypatch):
    # A task's two cameras, with and without the decimated meshes, at a pose that shows the jaws up close.
    simulator = BODIES[body].body_class()
    module = sys.modules[simulator.__module__]
    pictures = {}
    for decimated in (True, False):
        if not decimated:
            monkeypatch.setattr(module, "camera_meshes", lambda model_dir, log: None)
        with simulator(mode="direct", task=task_named("cube_to_box"), seed=3, light_pictures=True,
                       log=lambda line: None) as sim:
            sim.show_pose_deg([10, -20, 30, 40, 0, 20])
            pictures[decimated] = [sim.render_rgb(320, 240, camera).astype(int) for camera in (DEFAULT_CAMERA, WRIST_CAMERA)]
    for camera, light, full in zip(("front", "wrist"), pictures[True], pictures[False]):
        difference = np.abs(light - full).max(axis=2)
        # Measured: front 0.1-0.2 of 255 on average, 0.1 % of pixels by more than 32; wrist 0.6-1.1, 0.7-1 %.
        assert difference.mean() < 2.0, camera
        assert np.mean(difference > 32) < 0.02, camera
        assert np.mean(np.abs(light - full) > 0) > 0.001, camera  # they are the decimated meshes, not the same ones


@pytest.mark.slow
def test_so101_assets_derives_the_camera_meshes(model_copy, capsys):
    from so101.cli.main import main

    assert main(["assets", "--dir", str(model_copy)]) == 0
    assert camera_meshes.meshes_problem(model_copy) is None
    assert "Camera meshes derived from the model's meshes (" in capsys.readouterr().out
