"""A camera's place and field of view, fitted to pictures of the arm moving: `so101 cameras --fit`.

Why the arm's outline: every picture of a task already shows the arm, its joint angles are known
(the dataset's states, or the real arm's servos), and the simulator draws it from any camera. A
printed marker (ArUco) would need a board laid where the arm works and is absent from recorded
episodes; the arm is always there, in the simulator's pictures and in a real camera's alike.

How:
- The arm in the pictures: each picture against a background made of the others where the arm, as
  the fit now draws it, is not (the floor, the box, and the arm's base, which never moves, left
  unknown); a pixel that differs shows the arm, softly between two levels chosen for the looks. No
  colour is assumed, so any floor, any light.
- The arm drawn: its pixels (MuJoCo's segmentation, so101.bodies.task_cameras) at each picture's
  joint angles from the camera being fitted, drawn at twice the size and averaged; the cube too,
  where the dataset says where it was.
- Both blurred, and their difference made small by Levenberg-Marquardt over seven numbers (the
  lens's place, its turn about its own axes, the field of view), each step's slopes taken by
  drawing the arm again. Blurred widely first, then less (STAGES): a start some centimetres and
  degrees off is drawn in; the last stage reads the outline to a fraction of a pixel.
- The residual: how far, on average, the drawn outline lies from the pictures' (pixels at the
  pictures' size). Above MAX_RESIDUAL_PX the fit starts again from a few places along the line of
  sight (KICKS), then is refused.

A pinhole camera: the principal point at the picture's centre, no lens distortion (a real lens's
distortion goes in the residual). The front camera only: the wrist camera moves with the jaws and
sees them still, so its pictures show no arm moving.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import numpy.typing as npt

from so101.bodies.camera import Camera
from so101.bodies.camera_file import CameraFile, orbit_of
from so101.bodies.physics import Physics, physics_from_metadata

FloatArray = npt.NDArray[np.float64]
Picture = npt.NDArray[np.uint8]

# Pictures fitted at once, spread over the episode (each step slower with more). 32 were tried: the lens came
# nearer on four offsets and farther on two (docs/experiments/fitting-cameras.md), at twice the time.
PICTURES = 16
# A pixel whose difference from the background is under the lower level (of 255) shows no arm, over the
# higher one it does. Which pair fits depends on the looks (a yellow arm on a beige floor is faint, a
# bright light's sheen loud): each stage takes the pair whose arm's outline lies nearest the drawn one.
LEVELS = ((6.0, 18.0), (12.0, 36.0), (20.0, 50.0))
LUMA = np.array([0.299, 0.587, 0.114], dtype=np.float32)
COLOUR_WEIGHT = 0.5
# The stages: the blur's width in pixels of a 320-wide picture, wide first (a far start), then fine; how
# many times smaller than the pictures that stage draws; and which of the seven it moves. The nearness
# and the field of view wait for a sharper outline: blurred, a nearer camera and a wider view look alike.
ALL, ACROSS = (0, 1, 2, 3, 4, 5, 6), (0, 1, 3, 4, 5)
STAGES = ((16.0, 4, ACROSS), (8.0, 2, ALL), (4.0, 1, ALL), (2.0, 1, ALL))
STEPS_PER_STAGE = 20
# Where a fit that did not converge starts again (mm nearer along its line of sight, degrees of field of view).
KICKS = ((40.0, 0.0), (-40.0, 0.0), (0.0, 4.0), (0.0, -4.0))


def _for_the_seven(place: float, turn_deg: float, view_deg: float) -> FloatArray:
    """One amount for each of the seven numbers a fit moves: the lens's place (3, m), its turn (3), its view."""
    return np.array([place] * 3 + [math.radians(turn_deg)] * 3 + [view_deg])


# The slopes' steps at a blur of 1 px (more, the wider the blur).
SLOPE_STEPS = _for_the_seven(5e-4, 0.05, 0.05)
# The dolly keeps the size of what lies this far ahead: about where the arm is from the camera.
DOLLY_AT_M = 0.6
SUPERSAMPLE = 2
# The most one step moves: 2 cm, 3°, 3° of field of view (a longer one is shortened, its direction kept).
MAX_STEP = _for_the_seven(0.02, 3.0, 3.0)
# Below these a step ends its stage: 0.05 mm, 0.005°, 0.005° of field of view.
STILL_STEP = _for_the_seven(5e-5, 0.005, 0.005)
MAX_RESIDUAL_PX = 0.8  # at 320 pixels wide; in proportion for others (a fit that converged: 0.25-0.75)
# Fewer moving pixels than this share of a picture, in every picture: the camera shows no arm moving.
MIN_MOVED_SHARE = 0.002
# A picture's background leaves out the drawn arm widened by this many blurs: room for the fit's error.
MARGIN_BLURS = 3.0
MAX_MARGIN_PX = 24.0  # at 320 pixels wide: wider, too little of the picture is left to tell


class CameraFitError(ValueError):
    """A fit that cannot be made or did not converge; str() is one line."""


@dataclass(frozen=True)
class Pose:
    """A camera as the fit moves it: the lens's place, its axes (columns: right, up, forward) and field of view."""

    eye: FloatArray
    axes: FloatArray
    fov_deg: float

    @classmethod
    def of(cls, camera: CameraFile) -> "Pose":
        eye, forward, right, up = (np.asarray(axis, dtype=float) for axis in orbit_of(camera).axes())
        return cls(eye, np.column_stack([right, up, forward]), camera.fov_deg)

    def moved(self, step: npt.ArrayLike) -> "Pose":
        """Moved by (right, up: metres along its own axes; dolly: metres forward, its field of view widened
        so that what lies DOLLY_AT_M ahead keeps its size; turns about its right, up, forward axes, rad;
        zoom: degrees more field of view). A camera moved forward and widened at once changes the arm's
        picture little: the dolly is one of the seven, so the fit's steps can follow it."""
        right, up, dolly, *turn, zoom = (float(value) for value in np.asarray(step, dtype=float))
        half = math.tan(math.radians(self.fov_deg) / 2) * DOLLY_AT_M / (DOLLY_AT_M - dolly)
        fov = math.degrees(2 * math.atan(half)) + zoom
        eye = self.eye + self.axes @ np.array([right, up, dolly])
        return Pose(eye, self.axes @ _rotation(np.array(turn)), fov)

    def camera_file(self, width: int, height: int, residual_px: float | None = None) -> CameraFile:
        """As a camera file: it looks at where its line of sight meets the table (or 0.5 m ahead)."""
        forward, up = self.axes[:, 2], self.axes[:, 1]
        ahead = -self.eye[2] / forward[2] if forward[2] < -0.05 else 0.5
        look_at = self.eye + ahead * forward
        return CameraFile("front", _triple(self.eye), _triple(look_at), _triple(up), self.fov_deg, width, height,
                          residual_px)

    def camera(self) -> Camera:
        return orbit_of(self.camera_file(1, 1))


def _triple(vector: FloatArray) -> tuple[float, float, float]:
    return (float(vector[0]), float(vector[1]), float(vector[2]))


def _rotation(turn: FloatArray) -> FloatArray:
    """Rodrigues: the rotation by the vector `turn` (its length the angle, rad)."""
    angle = float(np.linalg.norm(turn))
    if angle < 1e-12:
        return np.eye(3)
    k = turn / angle
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    rotation: FloatArray = np.eye(3) + math.sin(angle) * cross + (1 - math.cos(angle)) * cross @ cross
    return rotation


def pose_error(fitted: CameraFile, truth: CameraFile) -> tuple[float, float, float]:
    """(metres between the lenses, degrees between their orientations, degrees between their fields of view)."""
    a, b = Pose.of(fitted), Pose.of(truth)
    turn = a.axes.T @ b.axes
    angle = math.degrees(math.acos(max(-1.0, min(1.0, (float(np.trace(turn)) - 1) / 2))))
    return float(np.linalg.norm(a.eye - b.eye)), angle, abs(a.fov_deg - b.fov_deg)


def arm_seen(pictures: npt.NDArray[np.uint8], drawn: FloatArray, margin_px: int,
             levels: tuple[float, float] = LEVELS[1]) -> tuple[FloatArray, FloatArray]:
    """Where each of (K, H, W, 3) pictures shows the arm, softly 0-1, and which pixels can tell (1) or not (0).

    A pixel's background is the median of the pictures whose drawn arm (K, H, W), widened by `margin_px`,
    is not on it: the arm as the fit now places it is left out, the floor and the box stay. A pixel the
    widened arm covers in every picture (the base) has no background, so it cannot tell."""
    import cv2

    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * margin_px + 1, 2 * margin_px + 1))
    near_arm = np.stack([cv2.dilate((mask > 0).astype(np.uint8), kernel) > 0 for mask in drawn])
    stack = pictures.astype(np.float32)
    hidden = np.where(near_arm[..., None], np.nan, stack)
    with warnings.catch_warnings():  # a pixel with no picture free of the arm has no background: nan, said below
        warnings.simplefilter("ignore", RuntimeWarning)
        background = np.nanmedian(hidden, axis=0)
    known = ~np.isnan(background[..., 0])
    apart = stack - np.nan_to_num(background)[None]
    # Brightness is sharp in a video; colour is kept at half the size (4:2:0), its edges a pixel wide: it counts half.
    difference = np.maximum(np.abs(apart @ LUMA), COLOUR_WEIGHT * np.abs(apart).max(axis=3))
    low, high = levels
    seen = np.clip((difference - low) / (high - low), 0.0, 1.0)
    return seen.astype(np.float64), known.astype(np.float64)


def _blurred(maps: FloatArray, sigma_px: float) -> FloatArray:
    import cv2

    stride = max(1, int(sigma_px / 2))
    blurred = [cv2.GaussianBlur(single.astype(np.float32), (0, 0), sigma_px)[::stride, ::stride] for single in maps]
    return np.stack(blurred).astype(np.float64)


def outline_distance_px(drawn: FloatArray, seen: FloatArray) -> float:
    """How far apart two sets of (K, H, W) maps' outlines (at 0.5) lie, on average both ways, in pixels."""
    import cv2

    distances = []
    for one, other in zip(drawn, seen):
        edges = []
        for single in (one, other):
            inside = (single > 0.5).astype(np.uint8)
            edges.append(inside - cv2.erode(inside, np.ones((3, 3), np.uint8)))
        if not edges[0].any() or not edges[1].any():
            continue
        for a, b in ((edges[0], edges[1]), (edges[1], edges[0])):
            away = cv2.distanceTransform((1 - b).astype(np.uint8), cv2.DIST_L2, 5)
            distances.append(float(away[a > 0].mean()))
    return float(np.mean(distances)) if distances else math.inf


class _Drawn:
    """The arm drawn at the chosen pictures' joint angles from any pose (one model, kept between draws)."""

    def __init__(self, angles_deg: Sequence[Sequence[float]], object_states: Sequence[Sequence[float]] | None,
                 physics: Physics | None = None):
        from so101.bodies.task_cameras import TaskCameras
        from so101.tasks import CUBE_TO_BOX

        self._cameras = TaskCameras(CUBE_TO_BOX, log=lambda line: None)
        self._cameras.show_physics(physics)  # the episode's cube, the arm where its calibration put it
        self._angles = [list(angles) for angles in angles_deg]
        self._objects = [list(state) for state in object_states] if object_states is not None else [[]] * len(self._angles)
        self.draws = 0

    def masks(self, pose: Pose, width: int, height: int) -> FloatArray:
        """The (K, height, width) share of each pixel the arm covers: drawn at twice the size, averaged
        2x2, so an outline that moves a fraction of a pixel changes the picture (the fit's slopes are smooth)."""
        camera = pose.camera()
        masks = np.stack([self._cameras.arm_mask(angles, camera, SUPERSAMPLE * width, SUPERSAMPLE * height, objects)
                          for angles, objects in zip(self._angles, self._objects)]).astype(np.float64)
        self.draws += len(self._angles)
        shares: FloatArray = masks.reshape(len(masks), height, SUPERSAMPLE, width, SUPERSAMPLE).mean(axis=(2, 4))
        return shares

    def close(self) -> None:
        self._cameras.close()


def fit_camera(pictures: Sequence[Picture], angles_deg: Sequence[Sequence[float]], start: CameraFile,
               object_states: Sequence[Sequence[float]] | None = None,
               log: Callable[[str], None] = lambda line: None, physics: Physics | None = None) -> CameraFile:
    """The front camera that saw `pictures` of the arm at `angles_deg` (one six-angle row each), from `start`,
    its residual_px the fit's;
    `object_states` (a task's, where a dataset has them) draw the cube too: it moves with the arm; `physics`
    (the episode's, as its dataset keeps it) draws its cube and the arm where its calibration put it."""
    if start.camera != "front":
        raise CameraFitError(f"only the front camera is fitted (the {start.camera} camera sees no arm moving)")
    if len(pictures) != len(angles_deg) or len(pictures) < 3:
        raise CameraFitError(f"a fit needs at least 3 pictures, each with its joint angles ({len(pictures)} pictures, "
                             f"{len(angles_deg)} rows of angles)")
    stack = np.stack([np.asarray(picture, dtype=np.uint8) for picture in pictures])
    height, width = stack.shape[1:3]
    most_px = MAX_RESIDUAL_PX * width / 320.0
    drawn = _Drawn(angles_deg, object_states, physics)
    try:
        pose, residual_px = _fit_stages(stack, drawn, Pose.of(start), STAGES, log)
        # A fit caught where a nearer camera with a narrower view (or the other way) looks almost alike:
        # it starts again from there, the sharper stages only, and keeps the best.
        for kick in KICKS:
            if residual_px <= most_px:
                break
            log(f"fit: the outline lies {residual_px:.2f} px off (at most {most_px:g}): again from {kick[0]:+.0f} mm "
                f"nearer, {kick[1]:+.0f}° of field of view")
            tried, tried_px = _fit_stages(stack, drawn, pose.moved([0, 0, kick[0] / 1000, 0, 0, 0, kick[1]]), STAGES[1:],
                                          log)
            if tried_px < residual_px:
                pose, residual_px = tried, tried_px
    finally:
        drawn.close()
    log(f"fit: the drawn outline lies {residual_px:.2f} px from the pictures' on average ({drawn.draws} drawings)")
    if not residual_px <= most_px:
        raise CameraFitError(f"the fit did not converge: the arm's outline lies {residual_px:.1f} px from the pictures' "
                             f"on average (at most {most_px:g} accepted): record the arm over a plain, light surface, "
                             "well lit (a faint outline misleads the fit), or start nearer with --near FILE "
                             "(so101 cameras --default front, edited to a tape measure's numbers)")
    return pose.camera_file(width, height, residual_px)


def _fit_stages(stack: npt.NDArray[np.uint8], drawn: "_Drawn", pose: Pose,
                stages: Sequence[tuple[float, int, tuple[int, ...]]],
                log: Callable[[str], None]) -> tuple[Pose, float]:
    """`stages` of the fit from `pose`: where it ends, and its outline's distance from the pictures' (px)."""
    import cv2

    height, width = stack.shape[1:3]
    for sigma, shrink, free in stages:
        # A wide blur sees no detail: its stages draw and compare smaller pictures, much faster.
        size = (max(8, round(width / shrink)), max(6, round(height / shrink)))
        small = stack if shrink == 1 else np.stack([cv2.resize(picture, size, interpolation=cv2.INTER_AREA)
                                                    for picture in stack])
        sigma_px = sigma * size[0] / 320.0
        margin_px = max(2, round(min(MARGIN_BLURS * sigma, MAX_MARGIN_PX) * size[0] / 320.0))

        levels = _levels(stack, drawn, pose)[0]

        def compared_at(near: Pose) -> Callable[[Pose], FloatArray]:
            """The stage's residual, its background made with the arm drawn at `near` (the fit so far)."""
            seen, known = arm_seen(small, drawn.masks(near, *size), margin_px, levels)
            if float((seen * known > 0.5).mean(axis=(1, 2)).max()) < MIN_MOVED_SHARE:
                raise CameraFitError("the pictures show no arm where it moves: is the camera on the arm, and did "
                                     "the arm move?")
            return lambda at: _blurred((drawn.masks(at, *size) - seen) * known[None], sigma_px).ravel()

        pose, taken = _levenberg_marquardt(pose, compared_at, sigma, free)
        log(f"fit: blur {sigma:g} px, {taken} steps: {_describe(pose)}")
    return pose, _levels(stack, drawn, pose)[1]


def _levels(stack: npt.NDArray[np.uint8], drawn: "_Drawn", pose: Pose) -> tuple[tuple[float, float], float]:
    """The LEVELS pair whose arm, seen in the pictures, has its outline nearest the arm drawn from `pose`, and that distance."""
    height, width = stack.shape[1:3]
    final = drawn.masks(pose, width, height)
    margin_px = max(2, round(MARGIN_BLURS * width / 320.0))
    distances = []
    for levels in LEVELS:
        seen, known = arm_seen(stack, final, margin_px, levels)
        distances.append((outline_distance_px(final * known[None], seen * known[None]), levels))
    distance, levels = min(distances)
    return levels, distance


def _describe(pose: Pose) -> str:
    eye = ", ".join(f"{1000 * value:.1f}" for value in pose.eye)
    return f"lens at ({eye}) mm, field of view {pose.fov_deg:.2f}°"


def _levenberg_marquardt(pose: Pose, compared_at: Callable[[Pose], Callable[[Pose], FloatArray]], sigma: float,
                         free: tuple[int, ...]) -> tuple[Pose, int]:
    """Up to STEPS_PER_STAGE steps of LM from `pose`, moving the seven numbers in `free`. Each step first
    remakes the background where the arm is drawn now (`compared_at`), then takes the slopes: central
    differences over about half a pixel's move of the outline (more, the wider the blur)."""
    slope_steps = SLOPE_STEPS * max(sigma, 2.0)
    damping = 1e-3
    for taken in range(1, STEPS_PER_STAGE + 1):
        residual = compared_at(pose)
        now = residual(pose)
        cost = float(now @ now)
        slopes = np.column_stack([
            (residual(pose.moved(np.eye(7)[i] * slope_steps[i])) - residual(pose.moved(-np.eye(7)[i] * slope_steps[i])))
            / (2 * slope_steps[i]) if i in free else np.zeros_like(now) for i in range(7)])
        normal = slopes.T @ slopes
        gradient = slopes.T @ now
        while True:
            step = -np.linalg.solve(normal + damping * np.diag(np.diag(normal)) + np.diag(1e-12 + (np.diag(normal) == 0)),
                                    gradient)
            step *= min(1.0, float(np.min(MAX_STEP / np.maximum(np.abs(step), 1e-12))))  # no leap to a far valley
            after = residual(pose.moved(step))
            if float(after @ after) < cost:
                pose = pose.moved(step)
                damping = max(damping / 3, 1e-7)
                break
            damping *= 4
            if damping > 1e4:
                return pose, taken
        if np.all(np.abs(step) < STILL_STEP):
            return pose, taken
    return pose, STEPS_PER_STAGE


def chosen_frames(length: int, count: int | None = None) -> list[int]:
    """`count` (default PICTURES) frame indices spread evenly over an episode of `length` frames (all of them when fewer)."""
    count = PICTURES if count is None else count
    if length <= count:
        return list(range(length))
    return [round(i * (length - 1) / (count - 1)) for i in range(count)]


def fit_from_dataset(root: Path, start: CameraFile, episode: int = 0,
                     log: Callable[[str], None] = lambda line: None, units: str | None = None,
                     calibration: Path | None = None) -> CameraFile:
    """`start`'s camera fitted to episode `episode` of the LeRobot dataset at `root` (its video
    observation.images.NAME and its observation.state, read in its units: so101.dataset.units, with
    `units` and the recording follower's `calibration` where its meta does not say), from `start`."""
    from so101.dataset.features import ENVIRONMENT_KEY, STATE_KEY
    from so101.dataset.layout import DatasetError, episode_scenario
    from so101.dataset.reader import Dataset

    name = start.camera
    key = f"observation.images.{name}"
    try:
        dataset = Dataset.open(root)
        columns = dataset.episode_frames(episode)
        if STATE_KEY not in columns:
            raise CameraFitError(f"{root} has no {STATE_KEY}: the fit draws the arm where each frame's state says")
        states = dataset.episode_joints_deg(episode, dataset.joint_units(units, calibration, episode))[STATE_KEY]
        objects = columns.get(ENVIRONMENT_KEY)  # a simulated task's: where the cube was
        chosen = chosen_frames(len(states))
        wanted = set(chosen)
        pictures = [picture for index, picture in enumerate(dataset.episode_images(episode, key)) if index in wanted]
        physics = physics_from_metadata(episode_scenario(dataset.info, episode).get("physics", {"physics": "fixed"}))
    except DatasetError as error:  # it names the dataset
        raise CameraFitError(str(error)) from None
    except (ValueError, OSError) as error:
        raise CameraFitError(f"{root}: {error}") from None
    if len(pictures) != len(chosen):
        raise CameraFitError(f"{root}: episode {episode}'s video {key} has fewer pictures than its {len(states)} frames")
    log(f"fit: the {name} camera, from episode {episode} of {root} ({len(pictures)} pictures of {len(states)} frames, "
        f"{pictures[0].shape[1]}x{pictures[0].shape[0]})")
    return fit_camera(pictures, [states[index] for index in chosen], start,
                      None if objects is None else [objects[index] for index in chosen], log, physics)

