"""Contact pads on the gripper's two fingertips, so that a simulated gripper can hold a cube.

Both simulators collide the jaws through their meshes' convex hulls. The fixed jaw's hull wraps
the jaw and its housing and runs straight from the fingertip to the housing, so above the
fingertip it stands up to 3 mm proud of the jaw's face. A 25 mm cube between the jaws touched
the hulls on its top edges only, one point a jaw, and was squeezed out, down (measured in
PyBullet: contact normals 13-40° off the horizontal; the cube stayed on the floor, or fell
within a second of the lift). The model files carry two flat pads for this, `fixed_jaw_pad` and
`moving_jaw_pad` in the MJCF, parallel when their faces are 40 mm apart, and switched off there
(their collision bits match nothing). Each is grown by `PAD_GROWTH_M` on its inner face, toward
the other jaw (34 mm apart when parallel), so that the cube touches pads only. With a task,
MuJoCo's pads are these grown boxes, switched on, and PyBullet gets the same boxes as extra
`<collision>` shapes of the same links: one source, the MJCF, for both. Without a task neither
simulator has them, and the arm moves as it always has.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass
from pathlib import Path

from so101.assets import ModelFilesError

PAD_GEOM_NAMES = ("fixed_jaw_pad", "moving_jaw_pad")
# Which way each pad's inner face looks, along its own x axis (tests/test_task_scene.py checks it with the kinematics).
INNER_FACE_SIGN = {"fixed_jaw_pad": 1.0, "moving_jaw_pad": -1.0}
# How much each pad grows on its inner face: past the fixed jaw's hull, where it stands proud of the pad.
PAD_GROWTH_M = 0.003


@dataclass(frozen=True)
class JawPad:
    """A pad as the MJCF has it: a box in its body's frame (the URDF link of the same name + `_link`)."""

    name: str
    body: str  # the MJCF body
    pos_m: tuple[float, float, float]
    quat_wxyz: tuple[float, float, float, float]
    half_size_m: tuple[float, float, float]

    @property
    def urdf_link(self) -> str:
        return f"{self.body}_link"

    @property
    def inward(self) -> tuple[float, float, float]:
        """The unit vector its inner face looks along, toward the other jaw, in its body's frame: its
        own x axis (the first column of its rotation), signed by INNER_FACE_SIGN."""
        w, x, y, z = self.quat_wxyz
        sign = INNER_FACE_SIGN[self.name]
        return (sign * (1 - 2 * (y * y + z * z)), sign * 2 * (x * y + w * z), sign * 2 * (x * z - w * y))

    def grown(self, by_m: float = PAD_GROWTH_M) -> "JawPad":
        """The pad `by_m` thicker on its inner face (its outer face stays where it is)."""
        pos = tuple(value + by_m / 2 * component for value, component in zip(self.pos_m, self.inward))
        half = (self.half_size_m[0] + by_m / 2, *self.half_size_m[1:])
        return JawPad(self.name, self.body, pos, self.quat_wxyz, half)  # type: ignore[arg-type]


def _numbers(text: str | None, count: int, default: tuple[float, ...] | None = None) -> tuple[float, ...]:
    if text is None and default is not None:
        return default
    values = tuple(float(value) for value in (text or "").split())
    if len(values) != count:
        raise ValueError(f"expected {count} numbers, got {text!r}")
    return values


def jaw_pads(mjcf: Path) -> tuple[JawPad, ...]:
    """The two pads of the MJCF at `mjcf`, as it has them; ModelFilesError, in one line, where it lacks them."""
    try:
        root = ElementTree.parse(mjcf).getroot()
        pads = {}
        for body in root.iter("body"):
            for geom in body.findall("geom"):
                if geom.get("name") in PAD_GEOM_NAMES and geom.get("type") == "box":
                    pads[geom.get("name")] = JawPad(
                        geom.get("name", ""), body.get("name", ""), _numbers(geom.get("pos"), 3),  # type: ignore[arg-type]
                        _numbers(geom.get("quat"), 4, (1.0, 0.0, 0.0, 0.0)), _numbers(geom.get("size"), 3),  # type: ignore[arg-type]
                    )
        return tuple(pads[name] for name in PAD_GEOM_NAMES)
    except (OSError, ElementTree.ParseError, ValueError, KeyError) as error:
        raise ModelFilesError(f"{mjcf}: no jaw pads {' and '.join(PAD_GEOM_NAMES)} to grasp with ({error})") from None


_MESH_FILE = re.compile(r'filename="([^"]+)"')


def urdf_with_pads(urdf_text: str, urdf_dir: Path, pads: tuple[JawPad, ...], rpy: dict[str, tuple[float, float, float]]) -> str:
    """The URDF with each pad a `<collision>` box of its link, and its mesh files named by absolute
    path (so the text loads from anywhere). `rpy[pad.name]` is the pad's orientation as URDF
    roll-pitch-yaw (PyBullet's getEulerFromQuaternion gives it)."""
    text = _MESH_FILE.sub(lambda match: f'filename="{(urdf_dir / match.group(1)).resolve()}"', urdf_text)
    for pad in pads:
        link_start = text.find(f'<link name="{pad.urdf_link}"')
        link_end = text.find("</link>", link_start)
        if link_start < 0 or link_end < 0:
            raise ModelFilesError(f"the URDF has no link {pad.urdf_link} for the jaw pad {pad.name}")
        xyz = " ".join(f"{value:.9g}" for value in pad.pos_m)
        angles = " ".join(f"{value:.9g}" for value in rpy[pad.name])
        size = " ".join(f"{2 * value:.9g}" for value in pad.half_size_m)
        collision = (f'  <!-- {pad.name}, from the MJCF (so101/bodies/jaw_pads.py) -->\n'
                     f'    <collision name="{pad.name}">\n      <origin xyz="{xyz}" rpy="{angles}"/>\n'
                     f'      <geometry>\n        <box size="{size}"/>\n      </geometry>\n    </collision>\n  ')
        text = text[:link_end] + collision + text[link_end:]
    return text
