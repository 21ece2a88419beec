"""The cameras' meshes: the model's visual meshes with fewer triangles, for a task's cameras.

A CPU renderer (PyBullet's TinyRenderer, MuJoCo through Mesa's llvmpipe) spends much of a
picture on the model's 322,564 triangles, most of them smaller than a pixel of a 320x240
picture. So each visual mesh is decimated by vertex clustering: the corners in one cell of a
grid of `CELL_M` become their mean, and a triangle left without three distinct corners goes.
A face keeps its corners' order, so it keeps facing out. Derived once (`so101 assets`,
or on demand), written beside the model with a manifest keyed like the collision hulls';
used with `light_pictures`: by the pictures a node publishes (so101.bodies.task_cameras), while
`so101 snapshot`, the window and the web view keep the full meshes.
`so101 bench --cameras` measures what they save.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np
import numpy.typing as npt

from so101 import assets
from so101.bodies.derived_files import folder_problem, writing_folder
from so101.bodies.stl import stl_bytes, stl_points

# Beside the URDF, made by `so101 assets` or on demand (never committed).
CAMERA_MESHES_DIR_NAME = "camera_meshes"
MANIFEST_NAME = "camera_meshes.sha256"
# The grid the corners snap to: a pixel of the front camera at 320x240 spans about 2.5 mm at the
# arm; the wrist camera sees the jaws from closer, and tests/test_camera_meshes.py bounds how far
# both cameras' pictures move.
CELL_M = 0.001
# What the cameras draw where the meshes cannot be derived.
FALLBACK = "the cameras draw the full meshes instead (the same pictures, slower)"

_VISUAL_BLOCK = re.compile(r"<visual>.*?</visual>", re.S)
_MESH_FILE = re.compile(r'filename="([^"]+)"')


class Decimated(NamedTuple):
    folder: Path  # the decimated STL files, named as the model's
    triangles: int  # over all meshes
    model_triangles: int


def cluster_vertices(corners: npt.ArrayLike, cell_m: float = CELL_M) -> npt.NDArray[np.float32]:
    """The triangles `corners` (triangles, 3, 3) with their corners clustered on a grid of
    `cell_m`: each corner moves to the mean of the corners in its cell, and triangles left
    with fewer than three distinct corners are dropped. Corner order is kept."""
    points = np.asarray(corners, dtype=np.float64).reshape(-1, 3)
    _, cell_of, counts = np.unique(np.floor(points / cell_m).astype(np.int64), axis=0,
                                   return_inverse=True, return_counts=True)
    cell_of = cell_of.reshape(-1)
    means = np.zeros((len(counts), 3))
    np.add.at(means, cell_of, points)
    means /= counts[:, None]
    faces = cell_of.reshape(-1, 3)
    kept = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    clustered: npt.NDArray[np.float32] = means[faces[kept]].astype(np.float32)
    return clustered


def meshes_key() -> str:
    """What derived files are valid for: the model files (their manifest) and the grid."""
    return f"vertex clustering {CELL_M} m; model {assets.manifest_digest()}"


def camera_meshes_dir(model_dir: Path) -> Path:
    return model_dir / CAMERA_MESHES_DIR_NAME


def model_meshes() -> list[str]:
    """The model's mesh files (relative paths), from its manifest."""
    return sorted(relpath for relpath in assets.manifest() if relpath.lower().endswith(".stl"))


def meshes_problem(model_dir: Path) -> str | None:
    """Why the derived files in `model_dir` cannot be used ("missing", ...), or None when they can."""
    return folder_problem(camera_meshes_dir(model_dir), MANIFEST_NAME, meshes_key(),
                          {Path(relpath).name for relpath in model_meshes()}, "derived from another model or grid")


def derive_camera_meshes(model_dir: Path) -> Decimated:
    """Write the decimated meshes into `model_dir` (a verified model); OSError where it cannot be written."""
    triangles = model_triangles = 0
    with writing_folder(camera_meshes_dir(model_dir), MANIFEST_NAME, meshes_key()) as staging:
        for relpath in model_meshes():
            corners = stl_points(model_dir / relpath).reshape(-1, 3, 3)
            kept = cluster_vertices(corners)
            name = Path(relpath).name
            (staging / name).write_bytes(stl_bytes(kept, f"{name} for cameras, derived by `{assets.FIX_COMMAND}`"))
            triangles += len(kept)
            model_triangles += len(corners)
    return Decimated(camera_meshes_dir(model_dir), triangles, model_triangles)


def camera_meshes(model_dir: Path, log: Callable[[str], None] = print) -> dict[str, Path] | None:
    """Each model mesh's file name -> its decimated file, derived now if missing or stale;
    None (said in `log`) where they cannot be written."""
    if meshes_problem(model_dir) is not None:
        try:
            derived = derive_camera_meshes(model_dir)
        except OSError as error:
            log(f"Camera meshes not derived: cannot write {camera_meshes_dir(model_dir)} "
                f"({error.strerror or error}); {FALLBACK}")
            return None
        log(f"Camera meshes derived from the model's meshes ({derived.triangles:,} of their "
            f"{derived.model_triangles:,} triangles): {derived.folder}")
    folder = camera_meshes_dir(model_dir)
    return {Path(relpath).name: folder / Path(relpath).name for relpath in model_meshes()}


def urdf_for_cameras(urdf_text: str, urdf_dir: Path, meshes: dict[str, Path]) -> str:
    """The URDF with each `<visual>` mesh its decimated file (`meshes`, by file name) and every
    other file named by absolute path, so the text loads from anywhere."""

    def decimated(block: re.Match[str]) -> str:
        return _MESH_FILE.sub(lambda mesh: f'filename="{meshes[Path(mesh.group(1)).name].resolve()}"', block.group(0))

    text = _VISUAL_BLOCK.sub(decimated, urdf_text)
    return _MESH_FILE.sub(lambda mesh: f'filename="{(urdf_dir / mesh.group(1)).resolve()}"', text)
