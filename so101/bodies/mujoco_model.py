"""MuJoCo's model of the scene: the MJCF's arm on a ground plane, its collision meshes as hulls.

MuJoCo collides a mesh geom through the mesh's convex hull alone, yet compiling the MJCF
builds everything for every full-resolution mesh (about 160,000 vertices: normals, BVH,
hull): a 390 MB peak. So the hulls MuJoCo computes for the collision meshes are derived
once (`so101 assets`, or on demand), saved beside the MJCF, and the scene's collision
geoms use them. The simulation node, when it draws nothing, compiles the scene without the
visual geoms (MuJoCo's `discardvisual`) and so without any full-resolution mesh.

The hulls' vertices are the STL files' own; only the frame MuJoCo centres each mesh in
moves (the hull's centroid, not the mesh's), so the arm in contact moves within
`HULL_TOLERANCE_DEG` of the MJCF compiled as written, and without contact bit for bit
(tests/test_mujoco_model.py).

This module imports mujoco first in this package: it chooses the OpenGL back end.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path
from typing import Any, Callable

import numpy as np
import numpy.typing as npt

from so101 import assets
from so101.bodies.jaw_pads import jaw_pads
from so101.bodies.protocol import SceneTask
from so101.bodies.stl import stl_points
from so101.runtime.display import choose_mujoco_gl

choose_mujoco_gl()
import mujoco  # noqa: E402

# Beside the MJCF, made by `so101 assets` (never committed); valid for one MuJoCo version.
HULLS_NAME = "so101_new_calib.mujoco_hulls.npz"
# The largest joint-angle difference, with contacts, from the MJCF compiled as written (measured: 3.3e-6°).
HULL_TOLERANCE_DEG = 1e-4
HULL_SUFFIX = "_hull"

# Mesh name -> (hull vertices in the STL's own coordinates, float32 (n, 3); triangles, int32 (m, 3)).
Hulls = dict[str, tuple[npt.NDArray[np.float32], npt.NDArray[np.int32]]]


def hulls_key() -> str:
    """What the saved hulls were derived with: this MuJoCo (its hull code) and the model files (their manifest)."""
    return f"mujoco {mujoco.__version__}; model {assets.manifest_digest()}"


def scene_model(mjcf: Path, hulls: Hulls | None, visual: bool = True, task: SceneTask | None = None,
                camera_meshes: dict[str, Path] | None = None) -> Any:
    """The MJCF's arm (a mujoco.MjModel) with what PyBullet's scene has too: a ground plane at z = 0 and a light.

    `hulls` None collides the MJCF's full meshes, as MuJoCo compiles the file; otherwise each
    collision geom uses its mesh's hull. `visual` False leaves out the visual geoms and their
    meshes: a model to step, not to draw. `task` adds its objects (its cube and box) and switches the
    jaw pads on, through its hook (so101.bodies.protocol.SceneTask.add_to_mujoco_spec). `camera_meshes` (file name -> file) draws
    the visual geoms with them (so101.bodies.camera_meshes).
    """
    spec = mujoco.MjSpec.from_file(str(mjcf))
    if hulls is not None:
        for name, (vertices, faces) in hulls.items():
            spec.add_mesh(name=name + HULL_SUFFIX, uservert=vertices.astype(np.float64).ravel().tolist(),
                          userface=faces.ravel().tolist())
        for geom in spec.geoms:
            if geom.type == mujoco.mjtGeom.mjGEOM_MESH and (geom.contype or geom.conaffinity):
                geom.meshname = geom.meshname + HULL_SUFFIX
    if camera_meshes is not None:  # after the hulls: only the visual geoms use the model's meshes now
        for mesh in spec.meshes:
            if mesh.file:
                mesh.file = str(camera_meshes[Path(mesh.file).name].resolve())
    spec.compiler.discardvisual = not visual
    spec.worldbody.add_geom(
        name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 0.05], rgba=[0.85, 0.87, 0.92, 1],
    )
    spec.worldbody.add_light(pos=[0.3, -0.3, 1.5], dir=[-0.2, 0.2, -1], type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)
    if task is not None:
        task.add_to_mujoco_spec(spec, tuple(pad.grown() for pad in jaw_pads(mjcf)))
    return spec.compile()


def stl_vertices(path: Path) -> npt.NDArray[np.float32]:
    """A binary STL's distinct vertices in the order they first appear: the order MuJoCo numbers them."""
    corners = stl_points(path)
    _, first = np.unique(corners, axis=0, return_index=True)
    return corners[np.sort(first)]


def derive_hulls(mjcf: Path) -> Hulls:
    """The convex hull MuJoCo computes for each collision mesh of the MJCF (a full compile, once)."""
    spec = mujoco.MjSpec.from_file(str(mjcf))
    files = {mesh.name: mjcf.parent / spec.meshdir / mesh.file for mesh in spec.meshes}
    model = scene_model(mjcf, hulls=None, visual=False)
    graph = model.mesh_graph
    hulls: Hulls = {}
    for mesh in range(model.nmesh):
        start = int(model.mesh_graphadr[mesh])
        if start < 0:  # no hull: a mesh no geom collides with
            continue
        name = model.mesh(mesh).name
        # mesh_graph: numvert, numface, vert_edgeadr, vert_globalid, edge_localid (numvert + 3 numface), face_globalid.
        hull_count, face_count = int(graph[start]), int(graph[start + 1])
        global_ids = graph[start + 2 + hull_count:start + 2 + 2 * hull_count]
        faces_start = start + 2 + 3 * hull_count + 3 * face_count
        faces = graph[faces_start:faces_start + 3 * face_count].reshape(-1, 3)
        vertices = stl_vertices(files[name])
        if len(vertices) != model.mesh_vertnum[mesh]:
            raise assets.ModelFilesError(
                f"{files[name]}: {len(vertices)} distinct vertices, MuJoCo read {model.mesh_vertnum[mesh]}; "
                f"run `{assets.FIX_COMMAND}` to fetch and verify it"
            )
        local_ids = np.full(len(vertices), -1, dtype=np.int32)
        local_ids[global_ids] = np.arange(hull_count, dtype=np.int32)
        hulls[name] = (vertices[global_ids], local_ids[faces])
    return hulls


def saved_hulls(path: Path) -> Hulls | None:
    """The hulls saved at `path`, or None where there are none or they were derived with another MuJoCo or model."""
    try:
        with np.load(path, allow_pickle=False) as saved:
            if str(saved["key"]) != hulls_key():
                return None
            names = sorted({entry.rsplit(".", 1)[0] for entry in saved.files if entry != "key"})
            return {name: (saved[f"{name}.vertices"], saved[f"{name}.faces"]) for name in names}
    except (OSError, ValueError, KeyError, zipfile.BadZipFile):
        return None


def save_hulls(path: Path, hulls: Hulls) -> None:
    """Write the hulls with their key; a reader sees the old file or the new one, never half of one."""
    arrays: dict[str, Any] = {"key": np.array(hulls_key())}
    for name, (vertices, faces) in hulls.items():
        arrays[f"{name}.vertices"], arrays[f"{name}.faces"] = vertices, faces
    partial = path.with_name(f".{path.name}.{os.getpid()}.partial")
    try:
        with partial.open("wb") as handle:
            np.savez(handle, **arrays)
        os.replace(partial, path)
    finally:
        partial.unlink(missing_ok=True)


def collision_hulls(mjcf: Path, log: Callable[[str], None] = print) -> Hulls:
    """The collision meshes' hulls for this MuJoCo: the saved ones, else derived now and saved beside the MJCF."""
    path = mjcf.with_name(HULLS_NAME)
    hulls = saved_hulls(path)
    if hulls is not None:
        return hulls
    hulls = derive_hulls(mjcf)
    try:
        save_hulls(path, hulls)
    except OSError as error:
        log(f"MuJoCo collision hulls derived from the MJCF's meshes, not saved ({error}): derived again on each start")
    else:
        log(f"MuJoCo collision hulls derived from the MJCF's meshes for mujoco {mujoco.__version__}: {path}")
    return hulls
