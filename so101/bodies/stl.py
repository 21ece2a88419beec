"""Binary STL files, the model's mesh format: read their triangle corners, write triangles back."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt

TRIANGLE = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])

PointArray = npt.NDArray[np.float32]


def stl_points(path: Path) -> PointArray:
    """A binary STL's triangle corners, float32 (3 · triangles, 3), as the file holds them."""
    data = path.read_bytes()
    count = int(np.frombuffer(data, "<u4", 1, 80)[0])
    return np.frombuffer(data, TRIANGLE, count, 84)["corners"].reshape(-1, 3)


def stl_bytes(corners: npt.ArrayLike, header: str) -> bytes:
    """A binary STL of the triangles `corners` (triangles, 3, 3), each with its unit normal
    (right-handed, from the corners' order; zero for a triangle with no area)."""
    corners = np.asarray(corners, dtype=np.float32).reshape(-1, 3, 3)
    triangles = np.zeros(len(corners), TRIANGLE)
    triangles["corners"] = corners
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]).astype(np.float64)
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    triangles["normal"] = np.divide(normals, lengths, out=np.zeros_like(normals), where=lengths > 0)
    return header.encode()[:80].ljust(80, b" ") + np.uint32(len(triangles)).tobytes() + triangles.tobytes()
