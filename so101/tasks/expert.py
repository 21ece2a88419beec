"""The scripted expert of `cube_to_box`: its plan, as plain functions, and the few checks it makes on the way.

The plan is a list of waypoints in joint space, each reached by a smooth move of a set
duration and then held: open the jaws above the cube, turned to its yaw; go down to it in
steps along the vertical; close; lift straight up; carry it over the box; lower it in;
open; go up and back to home. Every pose comes from the project's kinematics
(so101.tasks.grasp.TopDownGrasp, so101.kinematics.Kinematics), so the expert moves the
arm as any other sender does: six joint targets, in degrees.

`Expert` plays a plan out against time and looks at `object_state` at two moments: after
the lift and over the box (is the cube up with the jaws?). A cube that did not come up, or
fell on the way, gets a new plan from where the arm is to where the cube lies, up to
`MAX_ATTEMPTS` in all. It reads nothing but the arm's angles, the
gripper's and object_state, as a policy would.

`noise` perturbs a plan (where the approach, the carry and the release are, how fast it
moves, and a little where it grasps) from a seeded generator: demonstrations that do not
all look alike. `misses` is the share of episodes whose first grasp is put beside the cube on
purpose (`MISS_ASIDE_M`, any way round): the jaws close on nothing, the check after the lift
sees it, and the expert recovers. Until it does, it is `rehearsing`: a demonstration is the
recovery alone (nodes/episodes.py does not write those frames), for a policy which misses
needs to learn the way back, not the miss.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from so101.kinematics import TIP_LINK_INDEX, Kinematics
from so101.robot import HOME_POSE_DEG, NUM_ARM_JOINTS
from so101.tasks.cube_to_box import CubeToBox
from so101.tasks.grasp import TopDownGrasp

# The jaws, in the gripper's degrees: open leaves 62 mm between the pads' faces for the 25 mm cube
# (35° leaves 45 mm: see GRASP_CLEARANCE_M); closed is the goal the jaw squeezes toward (the cube stops it).
OPEN_DEG = 50.0
CLOSED_DEG = 0.0
# The cube's face this far from the fixed pad's as the jaws come down around it (the moving jaw,
# closing, pushes it across). Probed along the jaws' axis in both simulators, on two layouts, the jaws
# square or turned 15° either way: open 50°, every grasp from 10 mm toward the fixed jaw to 12 mm
# toward the moving one lifted the cube; open 35°, MuJoCo's turned 15° dropped it from 4 mm toward
# the moving jaw on one of them. So a policy that learns this grasp has about 10 mm to miss by
# either way (tests/test_task_scene.py holds it).
GRASP_CLEARANCE_M = 0.010
# The jaws' yaw over the cube: the cube's, within ±45°, turned half round. On that one of the four
# branches the wrist's roll stays within -66°…124° over the sector a cube starts in (the wrist turns
# ±157°); on the others it runs into its limits across the sector. Three layouts of seeds 0–99 and
# 1000–1049, at the sector's far corner, are out of the wrist's reach on it and take another.
GRASP_TURN_RAD = math.pi
# Heights of the grasp point (the cube's centre when held), metres above the floor.
APPROACH_ABOVE_M = 0.06  # above the cube, before going down
LIFT_ABOVE_M = 0.08  # the cube's lift off the floor
CARRY_CLEARANCE_M = 0.035  # the cube's bottom this far above the box's walls while carried
RELEASE_ABOVE_FLOOR_M = 0.015  # the cube's bottom this far above the box's floor when let go (held there, it is not in)
# Speeds of the moves, degrees per second of the joint that moves most; no move is shorter than MIN_MOVE_S.
FREE_DEG_S = 90.0
NEAR_DEG_S = 30.0  # down to the cube, up with it, into the box: slow, so the cube is not knocked or flung
MIN_MOVE_S = 0.25
# IK starts tried for a waypoint near the one before: from there it converges at once, or the pose
# cannot point straight down (near the base, the wrist's limit) and the carry tilts instead.
NEAR_STARTS = 2
DESCENT_STEPS = 4  # the way down to the cube, in this many waypoints along the vertical
CLOSE_S = 0.6  # the jaws closing on the cube, held still
OPEN_S = 0.4
SETTLE_S = 0.3  # held at the end of a move before the next starts
# A lift succeeded when the cube's centre is this much higher than on the floor.
LIFTED_M = 0.03
# The jaws hold the cube (Planner.holds_cube) when it is this far off the floor, they are shut below this angle
# (on the 25 mm cube they stop at 22° in PyBullet, 13° in MuJoCo; open is 50°), and its centre is this near the
# grasp point.
HELD_OFF_FLOOR_M = 0.01
HELD_JAWS_BELOW_DEG = 35.0
HELD_WITHIN_M = 0.025
MAX_ATTEMPTS = 3
# The noise at scale 1: standard deviations of the perturbations (metres, or a fraction of the time).
NOISE_APPROACH_M = 0.015
NOISE_GRASP_M = 0.003
NOISE_CARRY_M = 0.03
NOISE_RELEASE_M = 0.012
NOISE_TIME = 0.15
# A first grasp missed on purpose lands this far beside the cube's centre (metres, the least and the
# most), in a direction drawn at random: beyond the 10-12 mm a grasp may be off by and still lift it.
MISS_ASIDE_M = (0.030, 0.045)


@dataclass(frozen=True)
class Waypoint:
    """Six joint targets (five arm angles, then the gripper), reached in `move_s` and held `hold_s`."""

    targets_deg: tuple[float, ...]
    move_s: float
    hold_s: float
    phase: str  # what the arm does on its way here: approach, descend, close, lift, carry, lower, release, retreat, home
    check: str = ""  # "held": look whether the cube is up with the jaws, once here


@dataclass(frozen=True)
class CubeSeen:
    """The cube and the box as object_state gives them: the cube's centre and yaw, the box's footprint centre."""

    cube_xyz_m: tuple[float, float, float]
    cube_yaw_rad: float
    box_xyz_m: tuple[float, float, float]


def seen_in(object_state: Sequence[float]) -> CubeSeen:
    """The cube's centre and yaw (about the vertical; a cube on a face, x y z w quaternion) and the box's
    position, from an object_state in cube_to_box's OBJECT_STATE_NAMES order."""
    values = [float(value) for value in object_state]
    qx, qy, qz, qw = values[3:7]
    yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    return CubeSeen((values[0], values[1], values[2]), yaw, (values[7], values[8], values[9]))


def move_time_s(start_deg: Sequence[float], goal_deg: Sequence[float], speed_deg_s: float) -> float:
    """How long a move takes at `speed_deg_s` for the joint that turns most (the gripper's change counts too)."""
    largest = max(abs(goal - start) for goal, start in zip(goal_deg, start_deg))
    return max(MIN_MOVE_S, largest / speed_deg_s)


def smoothstep(fraction: float) -> float:
    """0 to 1 with zero speed at both ends (a cubic): the arm starts and stops gently."""
    t = min(1.0, max(0.0, fraction))
    return t * t * (3.0 - 2.0 * t)


def quarter_turn_rad(yaw_rad: float) -> float:
    """The yaw within [-45°, 45°) that a cube turned `yaw_rad` shows (a cube looks the same every 90°)."""
    return (yaw_rad + math.pi / 4) % (math.pi / 2) - math.pi / 4


def pan_rad(point: Sequence[float] | np.ndarray) -> float:
    """The bearing of a point from the base's axis: where shoulder_pan turns the arm to reach it."""
    return math.atan2(point[1], point[0])


class Planner:
    """Plans of `task` with `grasp` (its kinematics among it). Close it when done (it holds the kinematics')."""

    def __init__(self, task: CubeToBox, grasp: TopDownGrasp):
        self.task, self.grasp = task, grasp

    @property
    def kinematics(self) -> Kinematics:
        return self.grasp.kinematics

    def close(self) -> None:
        self.kinematics.close()

    def plan(self, seen: CubeSeen, start_deg: Sequence[float], noise: float = 0.0,
             draw: random.Random | None = None, grasp_aside_m: Sequence[float] = (0.0, 0.0)) -> list[Waypoint]:
        """The waypoints that put the cube `seen` into its box, from the arm at `start_deg` (six angles).
        `noise` > 0 perturbs them with `draw` (a seeded random.Random); `grasp_aside_m` (x, y) moves
        the grasp off the cube's centre (a miss on purpose)."""
        writing = _Writing(self, start_deg, noise, draw or random.Random(0))
        grasp_point = np.array(seen.cube_xyz_m) + writing.jitter(NOISE_GRASP_M) * [1, 1, 0]  # the cube's centre
        grasp_point[:2] += grasp_aside_m
        approach = grasp_point + [0, 0, APPROACH_ABOVE_M] + writing.jitter(NOISE_APPROACH_M)
        approach[2] = max(approach[2], grasp_point[2] + 0.03)
        release = self._release_point(seen, writing)
        arm = [float(angle) for angle in start_deg[:NUM_ARM_JOINTS]]

        # The yaw is chosen once, above the cube: the cube's own, taken within ±45°, turned by
        # GRASP_TURN_RAD (where the wrist reaches it: else the best of the four that grasp it), so that
        # the wrist's roll follows the cube's turn and place smoothly from one layout to the next, with
        # no jump by a quarter turn for a policy learning from these plans to average over. Every later
        # waypoint keeps it and starts its search from the waypoint before.
        first = self.grasp.pose_at_yaw(approach.tolist(), quarter_turn_rad(seen.cube_yaw_rad) + GRASP_TURN_RAD, seed_deg=arm)
        if not first.exact:
            first = self.grasp.pose(approach.tolist(), seen.cube_yaw_rad, seed_deg=arm)
        writing.yaw = first.yaw_rad
        above = first.arm_deg
        writing.add(above, OPEN_DEG, FREE_DEG_S, SETTLE_S, "approach")
        # Straight down: the grasp point's way along the vertical, in steps, the gripper's yaw kept.
        down = above
        top = np.array([grasp_point[0], grasp_point[1], approach[2]])
        for index in range(1, DESCENT_STEPS + 1):
            point = top + (grasp_point - top) * index / DESCENT_STEPS
            down = writing.pose(point, down)
            writing.add(down, OPEN_DEG, NEAR_DEG_S, SETTLE_S if index == DESCENT_STEPS else 0.0, "descend")
        writing.add(down, CLOSED_DEG, FREE_DEG_S, CLOSE_S, "close")
        lifted = down
        for index in range(1, 3):
            lifted = writing.pose(grasp_point + [0, 0, LIFT_ABOVE_M * index / 2], lifted, held=True)
            writing.add(lifted, CLOSED_DEG, NEAR_DEG_S, SETTLE_S if index == 2 else 0.0, "lift", "held" if index == 2 else "")
        self._carry(writing, grasp_point, lifted, np.array(seen.box_xyz_m), release)
        return writing.waypoints

    def plan_held(self, seen: CubeSeen, start_deg: Sequence[float], noise: float = 0.0,
                  draw: random.Random | None = None) -> list[Waypoint]:
        """The waypoints that put the cube `seen`, held in the jaws (holds_cube), into its box from the arm at
        `start_deg`: up to the lift's height where it is lower, then the plan's carry, lowering and release,
        the jaws kept at the yaw they hold it at (the expert taking over from whatever held it)."""
        writing = _Writing(self, start_deg, noise, draw or random.Random(0))
        release = self._release_point(seen, writing)
        arm = [float(angle) for angle in start_deg[:NUM_ARM_JOINTS]]
        writing.yaw = self.jaws_yaw_rad(arm)
        floor_point = np.array([seen.cube_xyz_m[0], seen.cube_xyz_m[1], self.task.cube.half_size_m])
        box_centre = np.array(seen.box_xyz_m)
        inner_m = self.task.box.inner_half_m - self.task.cube.half_size_m
        if np.all(np.abs(floor_point[:2] - box_centre[:2]) < inner_m):  # over the box already: down and let go
            release[:2] = box_centre[:2] + np.clip(floor_point[:2] - box_centre[:2], -inner_m + 0.01, inner_m - 0.01)
            self._put_in(writing, arm, release, 0.0)
            return writing.waypoints
        lifted = tuple(arm)
        if seen.cube_xyz_m[2] < floor_point[2] + LIFT_ABOVE_M:
            lifted = self.held_at(floor_point + [0, 0, LIFT_ABOVE_M], arm)
            writing.add(lifted, CLOSED_DEG, NEAR_DEG_S, SETTLE_S, "lift", "held")
        self._carry(writing, floor_point, lifted, np.array(seen.box_xyz_m), release)
        return writing.waypoints

    def _release_point(self, seen: CubeSeen, writing: "_Writing") -> np.ndarray:
        """Where the cube's centre is let go: low in the box, well inside its walls."""
        half, box = self.task.cube.half_size_m, self.task.box
        box_centre = np.array(seen.box_xyz_m)
        release = box_centre + [0, 0, box.floor_thickness_m + RELEASE_ABOVE_FLOOR_M + half]
        release[:2] += writing.jitter(NOISE_RELEASE_M, 2)
        inner = box.inner_half_m - half - 0.01  # the cube well inside the walls when let go
        release[:2] = box_centre[:2] + np.clip(release[:2] - box_centre[:2], -inner, inner)
        return release

    def _carry(self, writing: "_Writing", grasp_point: np.ndarray, lifted: Sequence[float], box_centre: np.ndarray,
               release: np.ndarray) -> None:
        """From the cube lifted above `grasp_point` (its centre's place on the floor) with the arm at `lifted`:
        over the box, down into it, the jaws open, up and home."""
        carry_z = box_centre[2] + self.task.box.wall_height_m + CARRY_CLEARANCE_M + self.task.cube.half_size_m
        # Over the box: through a point halfway, high, so the cube clears the box's near wall.
        via = (grasp_point + box_centre) / 2 + writing.jitter(NOISE_CARRY_M)
        # The noise raises it, never lowers it.
        via[2] = max(carry_z, grasp_point[2] + LIFT_ABOVE_M) + abs(via[2] - (grasp_point[2] + box_centre[2]) / 2)
        # Carried, the jaws turn with the arm's pan, so the wrist need not roll (a held cube may face any way).
        carried = writing.pose(via, lifted, held=True, turned_rad=pan_rad(via) - pan_rad(grasp_point))
        writing.add(carried, CLOSED_DEG, FREE_DEG_S * 0.6, 0.0, "carry")
        at_box_rad = pan_rad(release) - pan_rad(grasp_point)
        over_box = writing.pose(np.array([release[0], release[1], carry_z]), carried, held=True, turned_rad=at_box_rad)
        writing.add(over_box, CLOSED_DEG, FREE_DEG_S * 0.6, SETTLE_S, "carry", "held")
        self._put_in(writing, over_box, release, at_box_rad)

    def _put_in(self, writing: "_Writing", over_box: Sequence[float], release: np.ndarray, turned_rad: float) -> None:
        """From the cube held over the box (the arm at `over_box`): down to `release`, the jaws open, up and home."""
        carry_z = release[2] - self.task.box.floor_thickness_m - RELEASE_ABOVE_FLOOR_M + self.task.box.wall_height_m + CARRY_CLEARANCE_M
        lowered = writing.pose(release, over_box, held=True, turned_rad=turned_rad)
        writing.add(lowered, CLOSED_DEG, NEAR_DEG_S, SETTLE_S, "lower")
        writing.add(lowered, OPEN_DEG, FREE_DEG_S, OPEN_S, "release")
        up = writing.pose(np.array([release[0], release[1], carry_z + 0.02]), lowered, held=True, turned_rad=turned_rad)
        writing.add(up, OPEN_DEG, NEAR_DEG_S, 0.0, "retreat")
        writing.add(HOME_POSE_DEG[:NUM_ARM_JOINTS], HOME_POSE_DEG[NUM_ARM_JOINTS], FREE_DEG_S, 0.5, "home")

    def jaws_yaw_rad(self, arm_deg: Sequence[float]) -> float:
        """The yaw of the jaws' axis (the tip frame's x, on the table) with the arm at `arm_deg`."""
        _, rows = self.kinematics.frame_m(TIP_LINK_INDEX, arm_deg)
        x_axis = np.asarray(rows).reshape(3, 3)[:, 0]
        return math.atan2(x_axis[1], x_axis[0])

    def grasp_point_m(self, arm_deg: Sequence[float]) -> np.ndarray:
        """Where a cube held in the jaws has its centre, with the arm at `arm_deg` (base frame, metres)."""
        tip_xyz, rows = self.kinematics.frame_m(TIP_LINK_INDEX, arm_deg)
        return np.asarray(tip_xyz) + np.asarray(rows).reshape(3, 3) @ self.grasp.point_in_tip_m

    def holds_cube(self, seen: CubeSeen, joints_deg: Sequence[float]) -> bool:
        """Whether the jaws hold the cube now: shut on it, the cube off the floor, its centre at the grasp point."""
        off_floor = seen.cube_xyz_m[2] > self.task.cube.half_size_m + HELD_OFF_FLOOR_M
        shut = len(joints_deg) > NUM_ARM_JOINTS and joints_deg[NUM_ARM_JOINTS] < HELD_JAWS_BELOW_DEG
        near = float(np.linalg.norm(self.grasp_point_m(joints_deg[:NUM_ARM_JOINTS]) - np.asarray(seen.cube_xyz_m))) < HELD_WITHIN_M
        return off_floor and shut and near

    def held_at(self, point_m: np.ndarray, seed_deg: Sequence[float]) -> tuple[float, ...]:
        """Arm angles that put the grasp point at `point_m` with the gripper turned about as at `seed_deg`,
        where it cannot point straight down there (near the base, high up: the wrist's limit)."""
        tip_xyz, rows = self.kinematics.frame_m(TIP_LINK_INDEX, seed_deg)
        offset_m = np.asarray(rows).reshape(3, 3) @ self.grasp.point_in_tip_m
        return self.kinematics.solve((np.asarray(point_m) - offset_m) * 1000.0, seed_deg=seed_deg).joints_deg

    def recovery(self, seen: CubeSeen, now_deg: Sequence[float], noise: float, draw: random.Random) -> list[Waypoint]:
        """After a missed grasp: jaws open, up from where the arm is, then a new plan for the cube where it lies."""
        arm = [float(angle) for angle in now_deg[:NUM_ARM_JOINTS]]
        tip_mm = np.array(self.kinematics.tip_mm(arm))
        up = self.kinematics.solve(tip_mm + [0, 0, 50.0], seed_deg=arm)
        opened = (*arm, OPEN_DEG)
        lifted = (*up.joints_deg, OPEN_DEG)
        first = [Waypoint(opened, move_time_s(now_deg, opened, FREE_DEG_S), 0.0, "release"),
                 Waypoint(lifted, move_time_s(opened, lifted, NEAR_DEG_S), 0.0, "retreat")]
        return first + self.plan(seen, lifted, noise, draw)


class _Writing:
    """A plan being written: its waypoints from `start_deg`, the noise's draws, the jaws' yaw once chosen."""

    def __init__(self, planner: Planner, start_deg: Sequence[float], noise: float, draw: random.Random):
        self.planner, self.noise, self.draw = planner, noise, draw
        self.waypoints: list[Waypoint] = []
        self.last = tuple(float(angle) for angle in start_deg)
        self.yaw = 0.0

    def jitter(self, scale_m: float, count: int = 3) -> np.ndarray:
        return np.array([self.draw.gauss(0.0, scale_m * self.noise) for _ in range(count)]) if self.noise > 0 else np.zeros(count)

    def pace(self) -> float:
        """A move's duration, stretched by the noise (never hurried: a hurried carry flings)."""
        return 1.0 + abs(self.draw.gauss(0.0, NOISE_TIME * self.noise)) if self.noise > 0 else 1.0

    def add(self, arm_deg: Sequence[float], gripper_deg: float, speed_deg_s: float, hold_s: float, phase: str,
            check: str = "") -> None:
        targets = (*(float(angle) for angle in arm_deg), float(gripper_deg))
        self.waypoints.append(Waypoint(targets, move_time_s(self.last, targets, speed_deg_s) * self.pace(), hold_s, phase, check))
        self.last = targets

    def pose(self, point: np.ndarray, seed_deg: Sequence[float], held: bool = False, turned_rad: float = 0.0) -> tuple[float, ...]:
        """The arm angles that put the grasp point at `point`, the jaws at the plan's yaw (turned by `turned_rad`);
        a held cube where that cannot point straight down goes there tilted (Planner.held_at)."""
        found = self.planner.grasp.pose_at_yaw(point.tolist(), self.yaw + turned_rad, seed_deg, max_starts=NEAR_STARTS)
        return found.arm_deg if found.exact or not held else self.planner.held_at(point, seed_deg)


@dataclass
class Expert:
    """Plays plans out: `targets(now_s, ...)` gives the six joint targets for the time `now_s` (seconds,
    from any origin that only goes forward)."""

    planner: Planner
    noise: float = 0.0
    seed: int = 0
    misses: float = 0.0  # the chance that the first grasp is put beside the cube (MISS_ASIDE_M)
    plan: list[Waypoint] = field(default_factory=list)
    attempts: int = 0
    done: bool = False  # the plan played out to its end; `succeeded` is the task's own judgement
    _draw: random.Random = field(init=False)
    _started_s: float = 0.0
    _from_deg: tuple[float, ...] = ()
    _index: int = 0
    _checked: set[int] = field(default_factory=set)
    _missing: bool = False  # the first plan misses on purpose

    def __post_init__(self) -> None:
        self._draw = random.Random(self.seed)

    def start(self, now_s: float, joints_deg: Sequence[float], object_state: Sequence[float]) -> None:
        """A fresh plan for the scene as it is: a new episode."""
        self.attempts, self.done = 1, False
        aside_m = (0.0, 0.0)
        # Drawn only where misses > 0, so that without them the noise's draws are as they were.
        self._missing = self.misses > 0 and self._draw.random() < self.misses
        if self._missing:
            bearing, distance_m = self._draw.uniform(-math.pi, math.pi), self._draw.uniform(*MISS_ASIDE_M)
            aside_m = (distance_m * math.cos(bearing), distance_m * math.sin(bearing))
        seen = seen_in(object_state)
        if not self._missing and self.planner.holds_cube(seen, joints_deg):  # taking over a cube already held
            # The jaws keep squeezing from the start: their measured angle, where the cube stops them, is no squeeze.
            squeezing = (*joints_deg[:NUM_ARM_JOINTS], CLOSED_DEG)
            self._begin(now_s, squeezing, self.planner.plan_held(seen, joints_deg, self.noise, self._draw))
            return
        self._begin(now_s, joints_deg, self.planner.plan(seen, joints_deg, self.noise, self._draw, aside_m))

    def _begin(self, now_s: float, joints_deg: Sequence[float], plan: list[Waypoint]) -> None:
        self.plan, self._index, self._checked = plan, 0, set()
        self._started_s = now_s
        self._from_deg = tuple(float(angle) for angle in joints_deg)

    def targets(self, now_s: float, joints_deg: Sequence[float], object_state: Sequence[float]) -> tuple[float, ...]:
        """The six joint targets at `now_s`, given the arm's six angles and object_state now."""
        if not self.plan:
            self.start(now_s, joints_deg, object_state)
        while True:
            waypoint = self.plan[self._index]
            elapsed = now_s - self._started_s
            if elapsed < waypoint.move_s + waypoint.hold_s or self._index == len(self.plan) - 1:
                break
            if waypoint.check == "held" and self._index not in self._checked:
                self._checked.add(self._index)
                if not self._cube_up(object_state) and self.attempts < MAX_ATTEMPTS:
                    self.attempts += 1
                    self._begin(now_s, joints_deg, self.planner.recovery(seen_in(object_state), joints_deg,
                                                                         self.noise, self._draw))
                    continue
            self._from_deg = waypoint.targets_deg
            self._started_s += waypoint.move_s + waypoint.hold_s
            self._index += 1
        if self._index == len(self.plan) - 1 and now_s - self._started_s >= waypoint.move_s + waypoint.hold_s:
            self.done = True
        fraction = smoothstep((now_s - self._started_s) / waypoint.move_s)
        return tuple(start + (goal - start) * fraction for start, goal in zip(self._from_deg, waypoint.targets_deg))

    def _cube_up(self, object_state: Sequence[float]) -> bool:
        return seen_in(object_state).cube_xyz_m[2] > self.planner.task.cube.half_size_m + LIFTED_M

    @property
    def rehearsing(self) -> bool:
        """Playing a miss on purpose, its recovery not begun (to the end, where the cube came up all the same)."""
        return self._missing and self.attempts == 1

    @property
    def phase(self) -> str:
        return self.plan[self._index].phase if self.plan else ""


def takeover_frame(seed: int, most_s: float, fps: float) -> int:
    """The frame at which the expert takes over from a learner (DAgger) in the episode of layout `seed`: drawn
    evenly from 0 to `most_s` seconds, the same for the same seed."""
    return int(random.Random(f"takeover {seed}").uniform(0.0, most_s) * fps)


def planner_for(task: CubeToBox, assets_dir: str | None = None) -> Planner:
    """A planner of `task` on the project's kinematics, grasping with the fixed jaw's pad as the simulators have it."""
    from so101 import assets
    from so101.bodies.jaw_pads import jaw_pads

    kinematics = Kinematics(assets_dir)
    try:
        fixed_pad = jaw_pads(assets.mjcf_path(None if assets_dir is None else Path(assets_dir)))[0].grown()
    except BaseException:
        kinematics.close()
        raise
    return Planner(task, TopDownGrasp(kinematics, fixed_pad, task.cube.half_size_m, GRASP_CLEARANCE_M))
