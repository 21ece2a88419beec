"""Where the gripper tip is for five arm angles (FK), and five angles that put it at a point (IK).

Both come from PyBullet, on a client of its own that only does kinematics: the URDF is
loaded with a fixed base and without its meshes (`URDF_IGNORE_VISUAL_SHAPES |
URDF_IGNORE_COLLISION_SHAPES`, about 40 ms), nothing is ever stepped, and the solver is
PyBullet's `calculateInverseKinematics`. pybullet is imported when a `Kinematics` is made,
not when this module is: the prompt imports it and must start at once.

The frame is the arm's base frame, the URDF's `base_link`, in millimetres: x forward (the way
the gripper points at home), y to the arm's left, z up (checked by FK: shoulder_pan -30° moves
the tip to +y, shoulder_lift -30° raises it). The simulation puts this frame at its world
origin, so its ground plane is z = 0 here too. At home (all angles 0) the tip is at
(391.4, 0.0, 226.5) mm: the upper arm stands up, the forearm and gripper reach forward
level (tests/test_kinematics.py derives that point from the URDF's joint origins by hand).
Mind the signs: a positive shoulder_pan turns the arm to its right (y < 0) and a positive
shoulder_lift lowers it.

The tip is `gripper_frame_link`, the child of the fixed `gripper_frame_joint` (PyBullet
link 5): a point between the jaw tips, 98 mm out from the wrist_roll joint and 7.9 mm off
its axis (so wrist_roll moves it a little). The gripper's own angle does not move it.

Position-only IK on a five-joint arm has many answers and, from a single start, falls into
local minima: from home alone, with the refinement below, 9% of random reachable points end
more than 1 mm off (p99 84 mm). So `solve` tries starts in a fixed order: the arm's current
pose first (of several exact answers, the one nearest where the arm is wins), then home,
then SEEDS_COUNT fixed pseudo-random poses inside the limits. Each start is refined by
repeated calls, the joints reset to the last answer clamped to the limits each time: the
first NULL_SPACE_CALLS with PyBullet's null-space form (the URDF limits, rest pose = the
start), which keeps the answer inside the limits and near the start; the rest with plain
damped least squares and a small damping (DLS_DAMPING). PyBullet's default damping closes
only about 30% of the distance a call, and the null-space form alone stops 1-3 mm
short, pulled toward its rest pose; the mix gets within CONVERGED_MM in a few calls, about
1.5 ms a target in all.

An exact answer (within EXACT_MM) is taken if the arm can move to it from the current pose
without meeting the floor (`path_clear`); otherwise the starts go on, and if none gives
such an answer the exact one that comes least close to the floor is returned. Without
this, points near the base, low or behind it, got answers whose move from home swings the
gripper through the floor, where the simulated arm jams (`so101 reach --any-path` shows
it). IK itself knows nothing of the floor: a point under it can be "reachable".

For a point out of reach the answer nearest to it of all starts is returned: its tip is
the nearest reachable point IK found.
"""

from __future__ import annotations

import math
import random
import threading
from pathlib import Path
from typing import NamedTuple, Sequence

from so101 import assets
from so101.robot import ACTUATED_JOINTS, GRIPPER_FRAME_JOINT_INDEX, NUM_ARM_JOINTS

TIP_LINK_INDEX = GRIPPER_FRAME_JOINT_INDEX

# A solution farther than this from the target means "out of reach".
REACH_TOLERANCE_MM = 1.0
# An answer this close is exact: the first exact one whose way there is clear of the floor is taken.
EXACT_MM = 0.1
# Calls per start stop early once the answer is this close.
CONVERGED_MM = 0.01
CALLS_PER_START = 20
NULL_SPACE_CALLS = 3
DLS_DAMPING = 1e-3
SEEDS_COUNT = 40
SEEDS_RANDOM_SEED = 101
# The floor (the simulation's ground plane, a table for the real arm) is the plane z = 0.
# Along the way from the start to an answer, every link frame and the tip stay this high
# (or as high as they are at the start or the end, if lower), when some exact answer allows.
FLOOR_CLEARANCE_MM = 20.0
PATH_STEP_DEG = 5.0
CLEAR_SLACK_MM = 0.01  # rounding: a frame as high as at an end of the way is clear
# The links whose frames the floor check follows: upper arm (its frame is the shoulder_lift
# axis) to the moving jaw, and the tip. shoulder_link only turns about the vertical.
FLOOR_CHECKED_LINKS = (1, 2, 3, 4, TIP_LINK_INDEX, 6)


class Reach(NamedTuple):
    """An IK answer: the five arm angles, where they put the tip, and how far that is from the target."""

    joints_deg: tuple[float, ...]  # the five arm joints (shoulder_pan..wrist_roll), degrees, within the URDF limits
    tip_mm: tuple[float, float, float]  # where those joints put the tip (forward kinematics)
    error_mm: float  # distance from the target

    @property
    def reachable(self) -> bool:
        return self.error_mm <= REACH_TOLERANCE_MM


def _finite_numbers(values, count: int, what: str) -> tuple[float, ...]:
    """`count` finite floats, or ValueError in one line saying what was expected."""
    try:
        numbers = () if isinstance(values, (str, bytes)) else tuple(float(value) for value in values)
    except (TypeError, ValueError):
        numbers = ()
    if len(numbers) != count or not all(math.isfinite(number) for number in numbers):
        raise ValueError(f"expected {count} finite {what}, got {values!r}")
    return numbers


def arm_angles_deg(values) -> tuple[float, ...]:
    """The five arm angles as floats; ValueError for another count or a NaN/infinite angle."""
    return _finite_numbers(values, NUM_ARM_JOINTS, "arm joint angles in degrees")


def point_mm(values) -> tuple[float, float, float]:
    """x y z as floats; ValueError for another count or a NaN/infinite coordinate."""
    return _finite_numbers(values, 3, "coordinates x y z in mm")  # type: ignore[return-value]


class Kinematics:
    """FK and IK of the SO-101's gripper tip on a private, kinematics-only PyBullet client.

    Angles in degrees (the five arm joints, shoulder_pan..wrist_roll), points in mm in the
    base frame. Close it when done (or use `with`); closing twice is safe.
    """

    def __init__(self, assets_dir: Path | str | None = None):
        # The model first: a missing file must give our message, not PyBullet's.
        urdf = assets.urdf_path(Path(assets_dir) if assets_dir else None)
        import pybullet

        self._p = p = pybullet
        self.client = None
        # One client, one caller at a time: the prompt's pump thread reads where `xyz` landed
        # while its main thread may be solving the next.
        self._lock = threading.Lock()
        client = p.connect(p.DIRECT)
        if client < 0:
            raise RuntimeError("PyBullet could not connect in DIRECT mode")
        self.client = client
        try:
            self.robot_id = p.loadURDF(
                str(urdf), useFixedBase=True,
                flags=p.URDF_IGNORE_VISUAL_SHAPES | p.URDF_IGNORE_COLLISION_SHAPES,
                physicsClientId=client,
            )
            # calculateInverseKinematics works on every movable joint: the five arm joints and
            # the gripper (PyBullet indices 0-4 and 6), in index order.
            self._movable = [joint.index for joint in ACTUATED_JOINTS]
            infos = [p.getJointInfo(self.robot_id, index, physicsClientId=client) for index in self._movable]
        except Exception:
            self.close()
            raise
        self._lower_rad = [info[8] for info in infos]
        self._upper_rad = [info[9] for info in infos]
        self._ranges_rad = [upper - lower for lower, upper in zip(self._lower_rad, self._upper_rad)]
        self._gripper_rad = min(max(0.0, self._lower_rad[-1]), self._upper_rad[-1])
        # Fixed starts, the same every run and in every process.
        draw = random.Random(SEEDS_RANDOM_SEED)
        self._seeds_rad = [
            [draw.uniform(lower, upper) for lower, upper in zip(self._lower_rad, self._upper_rad)][:NUM_ARM_JOINTS]
            + [self._gripper_rad]
            for _ in range(SEEDS_COUNT)
        ]

    # -- helpers -----------------------------------------------------------------------
    def _connected(self) -> int:
        if self.client is None:
            raise RuntimeError("this Kinematics is closed")
        return self.client

    def _clamped(self, angles_rad: Sequence[float]) -> list[float]:
        return [min(max(angle, lower), upper) for angle, lower, upper in zip(angles_rad, self._lower_rad, self._upper_rad)]

    def _tip_m(self, angles_rad: Sequence[float]) -> tuple[float, float, float]:
        """Set all six movable joints to `angles_rad` and read the tip's link frame, in metres."""
        p, client, robot_id = self._p, self.client, self.robot_id
        for index, angle in zip(self._movable, angles_rad):
            p.resetJointState(robot_id, index, angle, physicsClientId=client)
        # [4] is the link's URDF frame (worldLinkFramePosition); [0] would be its centre of mass.
        return p.getLinkState(robot_id, TIP_LINK_INDEX, computeForwardKinematics=True, physicsClientId=client)[4]

    def _heights_mm(self, angles_rad: Sequence[float]) -> list[float]:
        """The height above the floor of each of FLOOR_CHECKED_LINKS' frames at a pose, mm."""
        p, client, robot_id = self._p, self.client, self.robot_id
        for index, angle in zip(self._movable, angles_rad):
            p.resetJointState(robot_id, index, angle, physicsClientId=client)
        states = p.getLinkStates(robot_id, FLOOR_CHECKED_LINKS, computeForwardKinematics=True, physicsClientId=client)
        return [state[4][2] * 1000.0 for state in states]

    def _path_margin_mm(self, start_rad: Sequence[float], goal_rad: Sequence[float], give_up_mm: float = -math.inf) -> float:
        """How near the arm comes to the floor moving from `start_rad` to `goal_rad` as the
        simulation moves it: every joint at the same top speed, so each heads straight for its
        goal and the ones with less to travel get there first. Each checked frame should stay
        FLOOR_CLEARANCE_MM high (or as high as it is at both ends, if lower, but never under
        the floor); the result is the least height over that, sampled every PATH_STEP_DEG of
        the longest travel: negative when the way is not clear. It stops early, with a figure
        below `give_up_mm`, as soon as the margin is known to be below `give_up_mm`."""
        deltas = [goal - start for start, goal in zip(start_rad, goal_rad)]
        longest = max(abs(delta) for delta in deltas)
        start_heights, goal_heights = self._heights_mm(start_rad), self._heights_mm(goal_rad)
        floors = [
            min(FLOOR_CLEARANCE_MM, max(0.0, min(start_height, goal_height)))
            for start_height, goal_height in zip(start_heights, goal_heights)
        ]
        margin = min(height - floor for height, floor in zip(goal_heights, floors))
        samples = math.ceil(longest / math.radians(PATH_STEP_DEG))
        for sample in range(1, samples):
            if margin < give_up_mm:
                break
            travel = longest * sample / samples
            pose = [start + math.copysign(min(travel, abs(delta)), delta) for start, delta in zip(start_rad, deltas)]
            margin = min(margin, min(height - floor for height, floor in zip(self._heights_mm(pose), floors)))
        return margin

    def _refine(self, target_m: list[float], start_rad: list[float]) -> tuple[list[float], float]:
        """Repeated IK calls from one start; (the last answer, clamped, and its error in metres)."""
        p, client, robot_id = self._p, self.client, self.robot_id
        angles = start_rad
        error_m = _distance(self._tip_m(angles), target_m)
        for call in range(CALLS_PER_START):
            if error_m < CONVERGED_MM / 1000.0:
                break
            if call < NULL_SPACE_CALLS:
                options = dict(
                    lowerLimits=self._lower_rad, upperLimits=self._upper_rad,
                    jointRanges=self._ranges_rad, restPoses=start_rad,
                )
            else:
                options = dict(jointDamping=[DLS_DAMPING] * len(self._movable))
            # The joints are where _tip_m left them: at `angles`, where this call starts.
            answer = p.calculateInverseKinematics(robot_id, TIP_LINK_INDEX, target_m, physicsClientId=client, **options)
            angles = self._clamped(answer)
            angles[-1] = self._gripper_rad
            error_m = _distance(self._tip_m(angles), target_m)
        return angles, error_m

    # -- the API -----------------------------------------------------------------------
    def path_clear(self, start_deg, goal_deg) -> bool:
        """Whether the arm keeps clear of the floor moving from five angles to five others as the
        simulation node moves it (each joint straight for its goal at the same top speed).

        A guide, not a collision check: it follows the frames of the joints from the
        shoulder_lift on and the tip (see _path_margin_mm), not the meshes around them.
        """
        start, goal = arm_angles_deg(start_deg), arm_angles_deg(goal_deg)
        with self._lock:
            self._connected()
            return self._path_margin_mm(
                self._clamped([math.radians(angle) for angle in start] + [self._gripper_rad]),
                self._clamped([math.radians(angle) for angle in goal] + [self._gripper_rad]),
            ) >= -CLEAR_SLACK_MM

    def tip_mm(self, arm_deg) -> tuple[float, float, float]:
        """Where five arm angles (degrees) put the tip, in mm in the base frame (forward kinematics)."""
        arm = arm_angles_deg(arm_deg)
        with self._lock:
            self._connected()
            tip_m = self._tip_m([math.radians(angle) for angle in arm] + [self._gripper_rad])
        return tuple(coordinate * 1000.0 for coordinate in tip_m)  # type: ignore[return-value]

    def solve(self, target_mm, seed_deg=None) -> Reach:
        """Five arm angles that put the tip at `target_mm` (x y z in mm, base frame), within the limits.

        `seed_deg`: the arm's current five angles (default home); tried first, so when several
        answers are exact the one nearest the current pose is preferred, among those the arm
        can move to from there clear of the floor. Out of reach, the answer is the nearest
        point found (`reachable` False, `error_mm` how far off). ValueError for a target
        that is not three finite numbers or a seed that is not five.
        """
        target_m = [coordinate / 1000.0 for coordinate in point_mm(target_mm)]
        seed = arm_angles_deg(seed_deg) if seed_deg is not None else (0.0,) * NUM_ARM_JOINTS
        with self._lock:
            return self._solve(target_m, seed)

    def _starts(self, seed_deg: Sequence[float]) -> list[list[float]]:
        """The poses IK starts from, in order (radians, the gripper's too): `seed_deg` clamped to the
        limits, home where it differs, then the fixed pseudo-random ones."""
        current = self._clamped([math.radians(angle) for angle in seed_deg] + [self._gripper_rad])
        home = self._clamped([0.0] * NUM_ARM_JOINTS + [self._gripper_rad])
        return [current] + ([home] if home != current else []) + self._seeds_rad

    def _solve(self, target_m: list[float], seed: Sequence[float]) -> Reach:
        self._connected()
        starts = self._starts(seed)
        current = starts[0]
        # The nearest answer, and the exact answer whose way is least blocked (see _path_margin_mm).
        nearest: list[float] = current
        nearest_error_m = math.inf
        exact: list[float] | None = None
        exact_margin_mm = -math.inf
        for start in starts:
            angles, error_m = self._refine(target_m, start)
            if error_m < nearest_error_m:
                nearest, nearest_error_m = angles, error_m
            if error_m < EXACT_MM / 1000.0:
                margin_mm = self._path_margin_mm(current, angles, give_up_mm=exact_margin_mm)
                if margin_mm > exact_margin_mm:
                    exact, exact_margin_mm = angles, margin_mm
                if exact_margin_mm >= -CLEAR_SLACK_MM:
                    break
        best_angles = exact if exact is not None else nearest
        tip_m = self._tip_m(best_angles)
        x_m, y_m, z_m = tip_m
        return Reach(
            joints_deg=tuple(math.degrees(angle) for angle in best_angles[:NUM_ARM_JOINTS]),
            tip_mm=(x_m * 1000.0, y_m * 1000.0, z_m * 1000.0),
            error_mm=_distance(tip_m, target_m) * 1000.0,
        )

    def solve_oriented(self, target_mm, rotation, seed_deg=None, max_starts: int | None = None) -> tuple[tuple[float, ...], float, float]:
        """Five arm angles that put the tip at `target_mm` with its frame turned as `rotation` (a
        3x3 matrix, its columns the tip's axes in the base frame), within the limits: (angles in
        degrees, position error in mm, angle error in degrees). A five-joint arm cannot take every
        orientation: the errors say how near it came. The starts are tried as `solve` tries them
        (`seed_deg`, default home, first), until one comes within EXACT_MM and 0.1°; `max_starts` tries
        no more than that many (a seed near the answer finds it from the first: a planner's next waypoint)."""
        import numpy as np
        # MuJoCo's matrix-to-quaternion (PyBullet has none), imported as every module here imports it.
        from so101.runtime.display import choose_mujoco_gl

        choose_mujoco_gl()
        import mujoco

        target_m = [coordinate / 1000.0 for coordinate in point_mm(target_mm)]
        matrix = np.asarray(rotation, dtype=np.float64).reshape(3, 3)
        wxyz = np.zeros(4)
        mujoco.mju_mat2Quat(wxyz, matrix.ravel())
        quat_xyzw = [wxyz[1], wxyz[2], wxyz[3], wxyz[0]]
        seed = arm_angles_deg(seed_deg) if seed_deg is not None else (0.0,) * NUM_ARM_JOINTS
        p = self._p

        def refined(start: list[float]) -> tuple[list[float], float, float]:
            angles = start
            for _ in range(CALLS_PER_START):
                self._tip_m(angles)  # the joints where this call starts
                answer = p.calculateInverseKinematics(
                    self.robot_id, TIP_LINK_INDEX, target_m, quat_xyzw,
                    jointDamping=[DLS_DAMPING] * len(self._movable), physicsClientId=self.client)
                angles = self._clamped(answer)
                angles[-1] = self._gripper_rad
            tip_m = self._tip_m(angles)
            reached = p.getLinkState(self.robot_id, TIP_LINK_INDEX, computeForwardKinematics=True,
                                     physicsClientId=self.client)[5]
            reached_matrix = np.asarray(p.getMatrixFromQuaternion(reached)).reshape(3, 3)
            cosine = (np.trace(reached_matrix.T @ matrix) - 1) / 2
            return angles, _distance(tip_m, target_m) * 1000.0, math.degrees(math.acos(min(1.0, max(-1.0, cosine))))

        with self._lock:
            self._connected()
            best: tuple[list[float], float, float] | None = None
            for start in self._starts(seed)[:max_starts]:
                found = refined(start)
                if best is None or found[1] + found[2] < best[1] + best[2]:
                    best = found
                if best[1] < EXACT_MM and best[2] < 0.1:
                    break
        assert best is not None
        angles, position_error_mm, angle_error_deg = best
        return tuple(math.degrees(angle) for angle in angles[:NUM_ARM_JOINTS]), position_error_mm, angle_error_deg

    def frame_m(self, link_index: int, arm_deg=None) -> tuple[tuple[float, float, float], tuple[float, ...]]:
        """A link's URDF frame at five arm angles (default home), the gripper closed: (origin in
        metres, rotation as 9 numbers, row-major), in the base frame."""
        arm = arm_angles_deg(arm_deg) if arm_deg is not None else (0.0,) * NUM_ARM_JOINTS
        p = self._p
        with self._lock:
            client = self._connected()
            self._tip_m([math.radians(angle) for angle in arm] + [self._gripper_rad])
            state = p.getLinkState(self.robot_id, link_index, computeForwardKinematics=True, physicsClientId=client)
        return tuple(state[4]), tuple(p.getMatrixFromQuaternion(state[5]))

    # -- life cycle --------------------------------------------------------------------
    def close(self) -> None:
        """Disconnect the private client; safe to call twice."""
        with self._lock:
            if self.client is not None:
                try:
                    self._p.disconnect(physicsClientId=self.client)
                except self._p.error:
                    pass
                self.client = None

    def __enter__(self) -> "Kinematics":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _distance(a: Sequence[float], b: Sequence[float]) -> float:
    return math.sqrt(sum((x - y) ** 2 for x, y in zip(a, b)))
