"""What a real arm differs by, drawn from the episode's seed: `--physics varied`.

A policy trained on one cube, one set of servos and one perfect calibration learns those too. With
varied physics each episode's seed draws its own, within `PhysicsRanges` (DEFAULT_RANGES, or a JSON
file of ranges: `physics_ranges`):
- the cube: its size, mass and friction (its own coefficient: against the jaws and the floor);
- the servos: their stiffness and damping (times each simulator's own), a command delay, a speed limit;
- the calibration: each joint's zero off by up to ±N°, as a real calibration is: the arm reports
  the angles it believes it is at, and goes where it believes a target is;
- the gripper's torque limit.
`fixed` (the default) is the nominal point of the same physics (`NOMINAL`), through the same command path
and motors: the task's cube, the servos at their simulator's own gains, no delay, an exact calibration,
the STS3215's full 3.35 N·m at the gripper and the course's 3 rad/s speed limit (PyBullet's; MuJoCo's MJCF
has none, and its fixed physics keeps none). The same seed gives the same
physics on every machine and on both simulators (Python's `random.Random`, seeded by text). Pure: the
bodies (so101.bodies.pybullet_sim, so101.bodies.mujoco_sim) apply it, the renderer
(so101.bodies.task_cameras) draws the cube's size and the arm where it truly is, a dataset keeps it by
episode (`physics_metadata`), and so101.bodies.command_path puts the delay, the speed limit and the
calibration between a command and the joints, alike for both. No numpy: the prompt's settings read it.
"""

from __future__ import annotations

import functools
import json
import math
import random
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any, Iterable

from so101.robot import COURSE_MAX_VELOCITY_RAD_S

PHYSICS_MODES = ("fixed", "varied")
DEFAULT_PHYSICS = "fixed"
JOINTS = 6
# The jaws open 40 mm between their pads (so101.bodies.jaw_pads): a larger cube cannot be held.
JAWS_OPEN_M = 0.040


class PhysicsError(ValueError):
    """A physics mode or ranges file that cannot be used; str() is one line."""


@dataclass(frozen=True)
class PhysicsRanges:
    """Where varied physics is drawn from: each a (low, high), uniform; `calibration_deg` a ±bound.
    The docs' page (docs/loop/physics.md) says why each range."""

    cube_size_m: tuple[float, float] = (0.022, 0.028)  # ManiSkill's SO-100 grasp task; the fixed cube is 25 mm
    cube_mass_kg: tuple[float, float] = (0.010, 0.050)  # a printed cube (10 g) to a metal one (50 g); fixed 30 g
    cube_friction: tuple[float, float] = (0.6, 1.2)  # printed plastic to rubbery; fixed 1.0
    servo_stiffness: tuple[float, float] = (0.7, 1.3)  # times the simulator's own; LeRobot halves the STS3215's P
    servo_damping: tuple[float, float] = (0.7, 1.3)  # times the simulator's own
    command_delay_s: tuple[float, float] = (0.0, 0.15)  # a bus, a servo's loop; a real follower trails ~133 ms
    speed_limit_deg_s: tuple[float, float] = (150.0, 270.0)  # an STS3215 loaded, to its 0.222 s/60° unloaded
    calibration_deg: float = 2.0  # each joint's zero, ± this
    gripper_torque_nm: tuple[float, float] = (1.2, 3.35)  # below LeRobot's 50% limit, to the servo's full
    # None: the servos' response is servo_stiffness times each simulator's own. A range (`so101 physics --fit`
    # writes one): each simulator sets its own gain to close 63% of a small step's gap in this time.
    servo_time_constant_s: tuple[float, float] | None = None

    def check(self, source: str = "the ranges") -> "PhysicsRanges":
        """These ranges, or PhysicsError naming `source` and what does not make sense."""
        positive = ("cube_size_m", "cube_mass_kg", "cube_friction", "servo_stiffness", "speed_limit_deg_s",
                    "gripper_torque_nm", "servo_time_constant_s")
        for spec in fields(self):
            value = getattr(self, spec.name)
            if value is None and spec.name == "servo_time_constant_s":
                continue
            if spec.name == "calibration_deg":
                if not _finite(value) or value < 0:
                    raise PhysicsError(f"{source}: calibration_deg is a number of degrees >= 0 (each joint's zero ± it), "
                                       f"got {value!r}")
                continue
            if (not isinstance(value, tuple) or len(value) != 2 or not all(_finite(end) for end in value)
                    or value[0] > value[1]):
                raise PhysicsError(f"{source}: {spec.name} is [low, high], two numbers, low <= high; got {_shown(value)}")
            lowest_allowed = "above 0" if spec.name in positive else ">= 0"
            if value[0] < 0 or (spec.name in positive and value[0] <= 0):
                raise PhysicsError(f"{source}: {spec.name} must be {lowest_allowed}, got {_shown(value)}")
        if self.cube_size_m[1] > JAWS_OPEN_M:
            raise PhysicsError(f"{source}: cube_size_m up to {self.cube_size_m[1]:g} m is larger than the jaws open "
                               f"({JAWS_OPEN_M:g} m between the pads)")
        return self


DEFAULT_RANGES = PhysicsRanges()
# Why each default range is what it is (`so101 physics` prints them; docs/loop/physics.md says more).
RANGE_REASONS = {
    "cube_size_m": "ManiSkill's SO-100 grasp task draws 22-28 mm; the jaws open 40 mm between the pads",
    "cube_mass_kg": "a printed cube with sparse infill (10 g) to a metal one (50 g)",
    "cube_friction": "slippery printed plastic to rubbery: the cube's own coefficient, against the jaws and the floor",
    "servo_stiffness": "times the simulator's own gain: LeRobot halves the STS3215's P coefficient, and owners tune it",
    "servo_damping": "times the simulator's own damping",
    "command_delay_s": "a bus round trip, the servo's loop, a busy host: a real LeRobot follower's state trails "
                       "its action by about 4 frames at 30 fps (133 ms); `so101 physics --fit` measures yours",
    "speed_limit_deg_s": "an STS3215 loaded, up to its 0.222 s per 60 degrees unloaded",
    "calibration_deg": "each joint's zero, as a calibration by hand puts it (plus or minus)",
    "gripper_torque_nm": "LeRobot's half torque limit (about 1.7 N.m) to the servo's full 3.35 N.m",
    "servo_time_constant_s": "none unless set (`so101 physics --fit` sets it from your arm): the servos' time "
                             "constant, each simulator's gain set to reach it, in place of servo_stiffness",
}


def _finite(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _shown(value: object) -> str:
    return json.dumps(list(value)) if isinstance(value, tuple) else repr(value)


def ranges_from(data: object, source: str) -> PhysicsRanges:
    """Ranges from a JSON object (any of PhysicsRanges' fields; the others stay DEFAULT_RANGES'), checked."""
    if not isinstance(data, dict):
        raise PhysicsError(f"{source}: a physics ranges file is a JSON object of ranges, e.g. "
                           '{"cube_size_m": [0.022, 0.028]}')
    known = {spec.name for spec in fields(PhysicsRanges)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise PhysicsError(f"{source}: unknown range {unknown[0]!r}; the ranges are: {', '.join(sorted(known))}")
    values = {name: tuple(value) if isinstance(value, list) else value for name, value in data.items()}
    return PhysicsRanges(**{**asdict(DEFAULT_RANGES), **values}).check(source)


@functools.lru_cache(maxsize=8)
def _ranges_file(path: str) -> PhysicsRanges:
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as error:
        raise PhysicsError(f"cannot read physics ranges {path}: {error.strerror or error}") from None
    except json.JSONDecodeError as error:
        raise PhysicsError(f"{path} is not JSON (line {error.lineno}: {error.msg})") from None
    return ranges_from(data, path)


@functools.lru_cache(maxsize=8)
def _ranges_text(text: str) -> PhysicsRanges:
    try:
        return ranges_from(json.loads(text), "the physics ranges")
    except json.JSONDecodeError as error:
        raise PhysicsError(f"the physics ranges are not JSON ({error.msg})") from None


def physics_ranges(mode: str) -> PhysicsRanges | None:
    """`mode`'s ranges: None for fixed, DEFAULT_RANGES for varied, a file's for a path to a .json file, the
    object's for JSON text (as `physics_mode` hands it to nodes); PhysicsError in one line."""
    mode = mode.strip()
    if mode == "fixed":
        return None
    if mode == "varied":
        return DEFAULT_RANGES
    if mode.startswith("{"):
        return _ranges_text(mode)
    if mode.endswith(".json"):
        return _ranges_file(str(Path(mode).expanduser().resolve()))
    raise PhysicsError(f"unknown physics {mode!r}; use fixed, varied, or a JSON file of ranges (NAME.json)")


def physics_mode(mode: str) -> str:
    """`mode` checked, as nodes are told it: fixed, varied, or a ranges file's ranges as JSON text (a node
    on another machine has no such file); PhysicsError otherwise."""
    ranges = physics_ranges(mode)
    if mode.strip() in PHYSICS_MODES or ranges is None:
        return mode.strip()
    return json.dumps(asdict(ranges), sort_keys=True)


@dataclass(frozen=True)
class Physics:
    """One episode's physics: what the bodies change from their fixed physics."""

    seed: int
    cube_size_m: float
    cube_mass_kg: float
    cube_friction: float
    servo_stiffness: float
    servo_damping: float
    command_delay_s: float
    speed_limit_deg_s: float
    calibration_offsets_deg: tuple[float, ...]  # six: what each joint reports minus where it is
    gripper_torque_nm: float
    servo_time_constant_s: float | None = None  # None: servo_stiffness times each simulator's own servo

    @property
    def cube_half_size_m(self) -> float:
        return self.cube_size_m / 2

    def true_deg(self, believed_deg: Iterable[float]) -> list[float]:
        """Where the six joints are when the arm believes them at `believed_deg`."""
        return [float(angle) - offset for angle, offset in zip(believed_deg, self.calibration_offsets_deg, strict=True)]

    def as_metadata(self) -> dict[str, object]:
        metadata: dict[str, object] = json.loads(json.dumps(asdict(self)))
        if self.servo_time_constant_s is None:  # as datasets kept physics before there was one
            del metadata["servo_time_constant_s"]
        return metadata


# Fixed physics: the values every body runs at when nothing varies, the centre varied physics spreads around.
# The cube's are the task's own cube (so101.tasks.objects); the speed limit the course's maxVelocity, 3 rad/s.
COURSE_SPEED_LIMIT_DEG_S = math.degrees(COURSE_MAX_VELOCITY_RAD_S)
NOMINAL = Physics(
    seed=0, cube_size_m=0.025, cube_mass_kg=0.030, cube_friction=1.0, servo_stiffness=1.0, servo_damping=1.0,
    command_delay_s=0.0, speed_limit_deg_s=COURSE_SPEED_LIMIT_DEG_S, calibration_offsets_deg=(0.0,) * JOINTS,
    gripper_torque_nm=3.35,
)


def centred(ranges: PhysicsRanges) -> PhysicsRanges:
    """`ranges` drawn to their centres, the calibration exact: one physics, whatever the seed (a replay set
    against a recording)."""
    middles = {spec.name: (round(sum(value) / 2, 6),) * 2 for spec in fields(ranges)
               if isinstance(value := getattr(ranges, spec.name), tuple)}
    return PhysicsRanges(**middles, calibration_deg=0.0)


def draw_physics(seed: int, ranges: PhysicsRanges = DEFAULT_RANGES) -> Physics:
    """The physics of episode seed `seed` (a whole number >= 0) within `ranges`."""
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"a seed is a whole number >= 0, got {seed!r}")
    draw = random.Random(f"so101 physics {seed}")  # apart from the layout's and the looks' draws

    def within(bounds: tuple[float, float]) -> float:
        return round(draw.uniform(*bounds), 6)

    return Physics(
        seed=seed, cube_size_m=within(ranges.cube_size_m), cube_mass_kg=within(ranges.cube_mass_kg),
        cube_friction=within(ranges.cube_friction), servo_stiffness=within(ranges.servo_stiffness),
        servo_damping=within(ranges.servo_damping), command_delay_s=within(ranges.command_delay_s),
        speed_limit_deg_s=within(ranges.speed_limit_deg_s),
        calibration_offsets_deg=tuple(within((-ranges.calibration_deg, ranges.calibration_deg)) for _ in range(JOINTS)),
        gripper_torque_nm=within(ranges.gripper_torque_nm),
        # Drawn last: the other values of a seed stay what they were before there was a time constant.
        servo_time_constant_s=None if ranges.servo_time_constant_s is None else within(ranges.servo_time_constant_s),
    )


def physics_for(mode: str, seed: int) -> Physics | None:
    """`mode`'s physics for episode seed `seed`: None for fixed (each simulator's own)."""
    ranges = physics_ranges(mode)
    return None if ranges is None else draw_physics(seed, ranges)


def physics_from_metadata(entry: object) -> Physics | None:
    """An episode's physics as a dataset keeps it (`physics_metadata`): None for fixed physics; ValueError in
    one line for an entry this project did not write."""
    if not isinstance(entry, dict) or entry.get("physics") not in PHYSICS_MODES:
        raise ValueError(f"an episode's physics is {{\"physics\": \"fixed\"}} or the varied values drawn, got {entry!r}")
    if entry["physics"] == "fixed":
        return None
    names = [field.name for field in fields(Physics)]
    missing = [name for name in names if name not in entry and name != "servo_time_constant_s"]
    if missing:
        raise ValueError(f"an episode's varied physics has no {missing[0]!r}: it holds {', '.join(names)}")
    values: dict[str, Any] = {name: entry.get(name) for name in names}
    values["calibration_offsets_deg"] = tuple(float(offset) for offset in entry["calibration_offsets_deg"])
    return Physics(**values)


def physics_metadata(mode: str, seed: int) -> dict[str, object]:
    """What a dataset keeps of an episode's physics: {"physics": "fixed"}, or the varied physics drawn."""
    physics = physics_for(mode, seed)
    if physics is None:
        return {"physics": "fixed"}
    metadata: dict[str, object] = {"physics": "varied"}
    ranges = physics_ranges(mode)
    if mode.strip() != "varied" and ranges is not None:  # a file's ranges
        metadata["ranges"] = json.loads(json.dumps(asdict(ranges)))
    return {**metadata, **physics.as_metadata()}
