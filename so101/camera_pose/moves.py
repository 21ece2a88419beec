"""Which way to move a camera so that it stands where another does, in words a person holding it follows.

`move_in_words(current, target)`: from where the real camera stands (a fitted camera file) to where it
should (the simulated camera's file), in the camera's own terms, as seen from behind it: left/right,
up/down, forward/back for the move; turn (right/left), tilt (up/down) and roll (clockwise/anticlockwise)
for the aim, after the move; and how its field of view differs from the simulated one's (no hand fixes a
lens: it is said, not asked). Amounts too small to do by hand are left out. Pure: no simulator.
"""

from __future__ import annotations

import math

from so101.bodies.camera import Vector, cross, dot, look_at_axes, unit
from so101.bodies.camera_file import CameraFile

# A move or a turn below these is left out: below what a hand can set a camera to.
MOVE_MIN_M = 0.002
TURN_MIN_DEG = 0.3
IN_PLACE = "in place"


def _scaled_sum(x: float, a: Vector, y: float, b: Vector) -> Vector:
    return (x * a[0] + y * b[0], x * a[1] + y * b[1], x * a[2] + y * b[2])


def camera_axes(camera: CameraFile) -> tuple[Vector, Vector, Vector]:
    """(right, up, forward) of the camera's picture, unit and square, in its file's frame."""
    return look_at_axes(camera.position_m, camera.look_at_m, camera.up)


def amount(value: float) -> str:
    """A figure as the words say it: to a tenth, without a trailing .0 (2.1, 4, 0.3)."""
    text = f"{abs(value):.1f}"
    return text[:-2] if text.endswith(".0") else text


def move_in_words(current: CameraFile, target: CameraFile) -> str:
    """How to move the camera standing at `current` to stand at `target` (both in one frame: the same camera's
    files), e.g. "move the camera 2.1 cm left, 0.8 cm up; turn it 3° right, tilt it 2° down; roll it 1°
    clockwise; zoom: field of view 4° wider than the simulated one's"; "in place" when nothing is worth doing."""
    right, up, forward = camera_axes(current)
    shift = (target.position_m[0] - current.position_m[0], target.position_m[1] - current.position_m[1],
             target.position_m[2] - current.position_m[2])
    moves = [f"{amount(100 * along)} cm {positive if along > 0 else negative}"
             for along, positive, negative in ((dot(shift, right), "right", "left"), (dot(shift, up), "up", "down"),
                                               (dot(shift, forward), "forward", "back"))
             if abs(along) >= MOVE_MIN_M]
    # The aim, after the move: pan about the camera's up, then tilt about its new right, then roll about its sight.
    _, target_up, target_forward = camera_axes(target)
    across, along_up, ahead = dot(target_forward, right), dot(target_forward, up), dot(target_forward, forward)
    turn_deg = math.degrees(math.atan2(across, ahead))
    tilt_deg = math.degrees(math.atan2(along_up, math.hypot(across, ahead)))
    level_right = unit(_scaled_sum(ahead, right, -across, forward))  # the right after pan and tilt, before roll
    level_up = cross(level_right, target_forward)
    # Positive: the target's top leans to the right of where the top is now (clockwise, seen from behind).
    roll_deg = math.degrees(math.atan2(dot(target_up, level_right), dot(target_up, level_up)))
    aims = [f"{verb} {{it}} {amount(angle)}° {positive if angle > 0 else negative}"
            for angle, verb, positive, negative in ((turn_deg, "turn", "right", "left"), (tilt_deg, "tilt", "up", "down"))
            if abs(angle) >= TURN_MIN_DEG]
    clauses = []
    if moves:
        clauses.append("move {it} " + ", ".join(moves))
    if aims:
        clauses.append(", ".join(aims))
    if abs(roll_deg) >= TURN_MIN_DEG:
        clauses.append(f"roll {{it}} {amount(roll_deg)}° {'clockwise' if roll_deg > 0 else 'anticlockwise'}")
    wider_deg = current.fov_deg - target.fov_deg
    if abs(wider_deg) >= TURN_MIN_DEG:
        clauses.append(f"zoom: field of view {amount(wider_deg)}° {'wider' if wider_deg > 0 else 'narrower'} "
                       "than the simulated one's")
    if not clauses:
        return IN_PLACE
    # The first clause names the camera; the ones after say "it".
    text = "; ".join(clauses)
    return text.replace("{it}", "the camera", 1).replace("{it}", "it")
