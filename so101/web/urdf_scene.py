"""The URDF as a tree of frames for a 3D scene: plain XML reading and quaternion maths, no engine.

A browser scene (so101/web/view.py) nests one frame per joint under its parent link's frame, so
moving a joint is one rotation sent to the browser, and the browser's scene graph does the
forward kinematics. A joint's frame is its URDF origin followed by the rotation about its axis;
a link's visuals sit in its frame at their own origins. Quaternions are (w, x, y, z).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

Quaternion = tuple[float, float, float, float]
Vector = tuple[float, float, float]
IDENTITY: Quaternion = (1.0, 0.0, 0.0, 0.0)


def multiply(a: Quaternion, b: Quaternion) -> Quaternion:
    """The rotation `a` then, in its frame, `b` (the Hamilton product a·b)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


def axis_angle(axis: Vector, angle_rad: float) -> Quaternion:
    norm = math.sqrt(sum(component * component for component in axis)) or 1.0
    half = angle_rad / 2.0
    s = math.sin(half) / norm
    return (math.cos(half), axis[0] * s, axis[1] * s, axis[2] * s)


def rpy(roll: float, pitch: float, yaw: float) -> Quaternion:
    """URDF's fixed-axis roll, pitch, yaw: about x, then y, then z of the parent frame."""
    return multiply(axis_angle((0, 0, 1), yaw), multiply(axis_angle((0, 1, 0), pitch), axis_angle((1, 0, 0), roll)))


def rotate(q: Quaternion, v: Vector) -> Vector:
    w, x, y, z = multiply(multiply(q, (0.0, *v)), (q[0], -q[1], -q[2], -q[3]))
    return (x, y, z)


@dataclass(frozen=True)
class Visual:
    link: str
    mesh_file: Path
    xyz: Vector
    wxyz: Quaternion
    rgba: tuple[float, float, float, float]


@dataclass(frozen=True)
class Joint:
    name: str
    movable: bool  # revolute; False for fixed
    parent: str
    child: str
    xyz: Vector
    wxyz: Quaternion  # the origin's rotation
    axis: Vector

    def rotation(self, angle_rad: float) -> Quaternion:
        """The child link's frame in the parent's: the origin's rotation, then `angle_rad` about the axis."""
        return multiply(self.wxyz, axis_angle(self.axis, angle_rad)) if self.movable else self.wxyz


@dataclass(frozen=True)
class UrdfScene:
    root_link: str
    joints: tuple[Joint, ...]  # parents before children
    visuals: tuple[Visual, ...]

    def link_path(self, link: str, prefix: str = "/arm") -> str:
        """The scene name of a link's frame: each joint nested under its parent link's."""
        by_child = {joint.child: joint for joint in self.joints}
        parts = []
        while link in by_child:
            joint = by_child[link]
            parts.append(joint.name)
            link = joint.parent
        return "/".join([prefix, self.root_link, *reversed(parts)])

    def link_poses(self, angles_rad: Mapping[str, float]) -> dict[str, tuple[Vector, Quaternion]]:
        """Every link's frame in the root's, for joint angles by name (missing ones at 0): what the
        nested frames show, worked out here for tests and for a server that wants positions."""
        poses: dict[str, tuple[Vector, Quaternion]] = {self.root_link: ((0.0, 0.0, 0.0), IDENTITY)}
        for joint in self.joints:
            position, rotation = poses[joint.parent]
            offset = rotate(rotation, joint.xyz)
            poses[joint.child] = (
                (position[0] + offset[0], position[1] + offset[1], position[2] + offset[2]),
                multiply(rotation, joint.rotation(angles_rad.get(joint.name, 0.0))),
            )
        return poses


def _numbers(text: str | None, count: int, default: float = 0.0) -> tuple[float, ...]:
    values = tuple(float(word) for word in (text or "").split())
    return values if len(values) == count else (default,) * count


def _origin(element: ET.Element) -> tuple[Vector, Quaternion]:
    origin = element.find("origin")
    xyz = _numbers(origin.get("xyz") if origin is not None else None, 3)
    roll, pitch, yaw = _numbers(origin.get("rpy") if origin is not None else None, 3)
    return (xyz[0], xyz[1], xyz[2]), rpy(roll, pitch, yaw)


def load_urdf_scene(urdf_file: Path) -> UrdfScene:
    """The URDF's links, joints and mesh visuals; mesh paths resolved beside the file."""
    robot = ET.parse(urdf_file).getroot()
    colours = {material.get("name"): _numbers(material.find("color").get("rgba"), 4, 1.0)  # type: ignore[union-attr]
               for material in robot.findall("material") if material.find("color") is not None}
    visuals = []
    for link in robot.findall("link"):
        for visual in link.findall("visual"):
            mesh = visual.find("geometry/mesh")
            if mesh is None:
                continue
            xyz, wxyz = _origin(visual)
            material = visual.find("material")
            rgba = colours.get(material.get("name") if material is not None else None, (0.8, 0.8, 0.8, 1.0))
            visuals.append(Visual(link.get("name", ""), urdf_file.parent / mesh.get("filename", ""), xyz, wxyz,
                                  (rgba[0], rgba[1], rgba[2], rgba[3])))
    joints = {}
    for element in robot.findall("joint"):
        xyz, wxyz = _origin(element)
        axis = _numbers(element.find("axis").get("xyz") if element.find("axis") is not None else None, 3)  # type: ignore[union-attr]
        joints[element.get("name", "")] = Joint(
            element.get("name", ""), element.get("type") in ("revolute", "continuous"),
            element.find("parent").get("link", ""), element.find("child").get("link", ""),  # type: ignore[union-attr]
            xyz, wxyz, (axis[0], axis[1], axis[2]))
    children = {joint.child for joint in joints.values()}
    roots = [link.get("name", "") for link in robot.findall("link") if link.get("name") not in children]
    if len(roots) != 1:
        raise ValueError(f"{urdf_file}: expected one root link, found {roots}")
    ordered: list[Joint] = []
    frontier = [roots[0]]
    while frontier:  # parents before children
        parent = frontier.pop(0)
        for joint in joints.values():
            if joint.parent == parent:
                ordered.append(joint)
                frontier.append(joint.child)
    return UrdfScene(roots[0], tuple(ordered), tuple(visuals))


def angles_by_joint(angles_deg: Sequence[float], joint_names: Sequence[str]) -> dict[str, float]:
    """Angles in degrees, in the order of `joint_names`, as radians by joint name."""
    return {name: math.radians(angle) for name, angle in zip(joint_names, angles_deg)}
