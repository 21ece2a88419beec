"""PyBullet's collision files: each collision mesh cut down to the points of its convex hull.

PyBullet collides a URDF's STL mesh through its convex hull alone, but it computes that
hull from every point of the full-resolution mesh, and room for all of them makes the
loading's memory peak (docs/benchmark.md, "Peak memory"). So each collision mesh's hull points are
derived once (`so101 assets`, or on demand), written as small STL files beside the model,
with a copy of the URDF whose `<collision>` meshes point at them; its `<visual>` meshes
stay the full ones, for pictures.

The equality rests on how PyBullet (Bullet's btConvexHullComputer) builds a hull: it snaps
every point to a grid of `HULL_GRID_STEPS` steps across the points' bounding box, per
axis, and returns the hull of the snapped points. A subset of the mesh's points with the
same bounding box and at least one source point of every hull vertex therefore gets the
very same hull vertices (their order differs). Derivation checks exactly that for each
mesh, and tests/test_course_motion.py that the arm then moves and touches the ground as
with the full meshes.
"""

from __future__ import annotations

import re
from importlib import metadata
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np
import numpy.typing as npt

from so101 import assets
from so101.bodies.derived_files import folder_problem, writing_folder
from so101.bodies.stl import TRIANGLE, stl_points

# Beside the URDF, made by `so101 assets` or on demand (never committed); valid for one PyBullet version.
HULLS_DIR_NAME = "pybullet_hulls"
# Lists every derived file's SHA-256 under a first line naming what they were derived with.
HULLS_MANIFEST_NAME = "hulls.sha256"
# What the simulator does where the hull files cannot be derived.
FALLBACK = "the simulator loads the full meshes instead (the same physics, more memory)"
# btConvexHullComputer's grid: the bounding box's extent on each axis, divided by this.
HULL_GRID_STEPS = 10216

_COLLISION_BLOCK = re.compile(r"<collision>.*?</collision>", re.S)
_MESH_FILE = re.compile(r'filename="([^"]+)"')

FloatArray = npt.NDArray[np.float64]
PointArray = npt.NDArray[np.float32]


class DerivedHulls(NamedTuple):
    urdf: Path  # the URDF whose collision meshes are the hull files
    hull_points: int  # the distinct points the hull files keep, over all collision meshes
    mesh_points: int  # the distinct points of those meshes


class HullMismatch(assets.ModelFilesError):
    """PyBullet builds another hull from a mesh's hull points than from the mesh itself."""


def hulls_key() -> str:
    """What derived files are valid for: this PyBullet (its hull code) and the model files (their manifest)."""
    return f"pybullet {metadata.version('pybullet')}; model {assets.manifest_digest()}"


# -- STL files ---------------------------------------------------------------------------


def point_stl_bytes(points: PointArray, header: str) -> bytes:
    """A binary STL whose triangles are `points` three by three (the last repeated to fill the
    last triangle): a point set for PyBullet's hull, not a surface to draw."""
    padded = np.concatenate([points, np.repeat(points[-1:], (-len(points)) % 3, axis=0)])
    triangles = np.zeros(len(padded) // 3, TRIANGLE)  # no normals: these are points, not faces
    triangles["corners"] = padded.reshape(-1, 3, 3)
    return header.encode()[:80].ljust(80, b" ") + np.uint32(len(triangles)).tobytes() + triangles.tobytes()


# -- the pure parts ----------------------------------------------------------------------


def hull_points(points: PointArray, hull_vertices: FloatArray) -> PointArray:
    """The distinct `points` PyBullet's hull of them may have come from: those within one grid
    step, on every axis, of one of its `hull_vertices`, and the extremes of each axis (they
    fix the grid). Sorted, so the result depends on the point set alone."""
    distinct = np.unique(points, axis=0)  # sorted rows: by x first
    as_float = distinct.astype(np.float64)
    step = (as_float.max(axis=0) - as_float.min(axis=0)) / HULL_GRID_STEPS
    keep = np.zeros(len(distinct), dtype=bool)
    for axis in range(3):
        keep[np.argmin(as_float[:, axis])] = keep[np.argmax(as_float[:, axis])] = True
    starts = np.searchsorted(as_float[:, 0], hull_vertices[:, 0] - step[0], side="left")
    ends = np.searchsorted(as_float[:, 0], hull_vertices[:, 0] + step[0], side="right")
    for vertex, start, end in zip(hull_vertices, starts, ends):
        near = np.all(np.abs(as_float[start:end] - vertex) <= step, axis=1)
        keep[start:end] |= near
    return distinct[keep]


def collision_urdf_text(urdf_text: str) -> str:
    """The URDF, to be written into the hulls' folder: each `<collision>` mesh is the hull file of
    the same name there, every other file the model's own, one folder up."""

    def rewrite(match: re.Match[str]) -> str:
        if match.group("file") is not None:
            return f'filename="../{match.group("file")}"'
        return _MESH_FILE.sub(lambda mesh: f'filename="{Path(mesh.group(1)).name}"', match.group(0))

    return re.sub(rf'{_COLLISION_BLOCK.pattern}|filename="(?P<file>[^"]+)"', rewrite, urdf_text, flags=re.S)


def collision_meshes(urdf_text: str) -> list[str]:
    """The mesh files the URDF's `<collision>` elements name, each once, in order."""
    names = [name for block in _COLLISION_BLOCK.findall(urdf_text) for name in _MESH_FILE.findall(block)]
    return list(dict.fromkeys(names))


def same_vertex_set(first: FloatArray, second: FloatArray) -> bool:
    """Exactly the same points, in any order."""
    return first.shape == second.shape and np.array_equal(np.unique(first, axis=0), np.unique(second, axis=0))


# -- PyBullet ----------------------------------------------------------------------------


def pybullet_hull_vertices(stl: Path, client: int) -> FloatArray:
    """The vertices of the hull PyBullet builds for `stl` as a collision mesh (as a URDF's
    `<collision>` does), in the mesh's own coordinates."""
    import pybullet as p

    shape = p.createCollisionShape(p.GEOM_MESH, fileName=str(stl), physicsClientId=client)
    body = p.createMultiBody(baseMass=0, baseCollisionShapeIndex=shape, physicsClientId=client)
    _, vertices = p.getMeshData(body, -1, physicsClientId=client)
    p.removeBody(body, physicsClientId=client)
    return np.asarray(vertices, dtype=np.float64)


def hulls_dir(urdf: Path) -> Path:
    return urdf.parent / HULLS_DIR_NAME


def hulls_problem(urdf: Path) -> str | None:
    """Why the derived files beside `urdf` cannot be used ("missing", ...), or None when they can."""
    return folder_problem(hulls_dir(urdf), HULLS_MANIFEST_NAME, hulls_key(), {urdf.name},
                          "derived with another PyBullet or model")


def derive_hulls(urdf: Path) -> DerivedHulls:
    """Write the hull files and the URDF that uses them beside `urdf` (a verified model). Raises
    HullMismatch where PyBullet would build another hull from the hull points, OSError where
    the folder cannot be written."""
    import pybullet as p

    text = urdf.read_text()
    kept_count = mesh_count = 0
    with writing_folder(hulls_dir(urdf), HULLS_MANIFEST_NAME, hulls_key()) as staging:
        client = p.connect(p.DIRECT)
        try:
            for relpath in collision_meshes(text):
                source = urdf.parent / relpath
                full_hull = pybullet_hull_vertices(source, client)
                target = staging / Path(relpath).name
                points = stl_points(source)
                kept = hull_points(points, full_hull)
                target.write_bytes(point_stl_bytes(kept, f"hull points of {source.name}, derived by `{assets.FIX_COMMAND}`"))
                kept_count += len(kept)
                mesh_count += len(np.unique(points, axis=0))
                if not same_vertex_set(pybullet_hull_vertices(target, client), full_hull):
                    raise HullMismatch(
                        f"pybullet {metadata.version('pybullet')} builds another hull from the hull points of "
                        f"{source.name} than from the mesh itself; {FALLBACK}"
                    )
        finally:
            p.disconnect(physicsClientId=client)
        (staging / urdf.name).write_text(collision_urdf_text(text))
    return DerivedHulls(hulls_dir(urdf) / urdf.name, kept_count, mesh_count)


def collision_hulls_urdf(urdf: Path, log: Callable[[str], None] = print) -> Path:
    """The URDF whose collision meshes are the hull files beside the verified `urdf`, derived now
    if they are missing or stale (raises like derive_hulls)."""
    if hulls_problem(urdf) is None:
        return hulls_dir(urdf) / urdf.name
    derived = derive_hulls(urdf)
    log(
        f"PyBullet collision hulls derived from the URDF's meshes for pybullet {metadata.version('pybullet')} "
        f"({derived.hull_points:,} of their {derived.mesh_points:,} points): {derived.urdf.parent}"
    )
    return derived.urdf


def urdf_to_load(urdf: Path, log: Callable[[str], None] = print) -> Path:
    """The URDF for the simulator: with the hull files (derived now if need be), else, where they
    cannot be derived, `urdf` itself with its full meshes (the same physics, more memory)."""
    try:
        return collision_hulls_urdf(urdf, log)
    except HullMismatch as error:
        log(f"PyBullet collision hulls not derived: {error}")
    except OSError as error:
        log(f"PyBullet collision hulls not derived: cannot write {hulls_dir(urdf)} ({error.strerror or error}); {FALLBACK}")
    return urdf

