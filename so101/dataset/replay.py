"""What the replay node does, without dora: the slow move to an episode's first frame, the
schedule that plays its actions at the dataset's rate, and the tracking error it reports.

Each frame's action (LeRobot's values, made degrees by so101.dataset.features.from_lerobot) is
compared with the state the body reached one frame later, just before the next action goes out:
what the body made of that command in the time the recording gave it.
"""

from __future__ import annotations

import math
import numpy as np
import numpy.typing as npt

from so101.robot import ACTUATED_JOINTS
from so101.stats import percentile

# How fast the move to the first frame may turn a joint (the gripper too): slow enough to watch,
# and under the real arm's own speed limit (SO101_MAX_SPEED_DEG_S, 90°/s by default).
RAMP_SPEED_DEG_S = 30.0
# After the move, play starts once every joint is this close to the first frame's action, or
# after SETTLE_TIMEOUT_S (a joint that gravity holds off its target must not stall replay).
SETTLED_DEG = 2.0
SETTLE_TIMEOUT_S = 2.0

FloatArray = npt.NDArray[np.float64]


def ramp_deg(start_deg: npt.ArrayLike, goal_deg: npt.ArrayLike, fps: float,
             speed_deg_s: float = RAMP_SPEED_DEG_S) -> FloatArray:
    """Waypoints, one per frame, from `start_deg` to `goal_deg` in a straight line in joint space,
    no joint faster than `speed_deg_s`; the last is `goal_deg` (a single one when already there)."""
    start, goal = np.asarray(start_deg, dtype=np.float64), np.asarray(goal_deg, dtype=np.float64)
    widest_deg = float(np.max(np.abs(goal - start)))
    frames = max(1, math.ceil(widest_deg / (speed_deg_s / fps)))
    fractions = np.arange(1, frames + 1, dtype=np.float64) / frames
    return start + fractions[:, None] * (goal - start)


def send_time_s(start_s: float, index: int, period_s: float, last_sent_s: float) -> float:
    """When frame `index` goes out: on the schedule from `start_s`, and never less than a period after
    the last one sent (at `last_sent_s`). A replay that wakes late goes on from there instead of
    sending the frames it missed in a burst: that burst would turn the joints faster than the ramp
    or the recording asks."""
    return max(start_s + index * period_s, last_sent_s + period_s)


def settled(state_deg: npt.ArrayLike, goal_deg: npt.ArrayLike, within_deg: float = SETTLED_DEG) -> bool:
    return bool(np.all(np.abs(np.asarray(state_deg) - np.asarray(goal_deg)) <= within_deg))


def tracking_errors_deg(actions_deg: npt.ArrayLike, reached_deg: npt.ArrayLike) -> FloatArray:
    """|action − reached| for every frame and joint, flattened (degrees)."""
    actions, reached = np.asarray(actions_deg, dtype=np.float64), np.asarray(reached_deg, dtype=np.float64)
    if actions.shape != reached.shape or actions.shape[-1:] != (len(ACTUATED_JOINTS),):
        raise ValueError(f"actions {actions.shape} and reached states {reached.shape} must both be (frames, 6)")
    return np.abs(actions - reached).ravel()


def tracking_line(errors_deg: npt.ArrayLike) -> str:
    """The replay's last line."""
    errors = [float(error) for error in np.ravel(errors_deg)]
    return (f"tracking error (deg): p50 {percentile(errors, 0.50):.2f}, p99 {percentile(errors, 0.99):.2f}, "
            f"max {max(errors):.2f}")


def versus_recording_line(reached_deg: npt.ArrayLike, recorded_states_deg: npt.ArrayLike) -> str:
    """How the body followed the recording: its joints just before frame i+1's action went out against the
    recording's observation.state of frame i+1, read at the same instant (LeRobot reads the state, then
    sends that frame's action). On a real recording, the body against the real arm."""
    reached, recorded = np.asarray(reached_deg, dtype=np.float64), np.asarray(recorded_states_deg, dtype=np.float64)
    errors = [float(error) for error in tracking_errors_deg(reached[:-1], recorded[1:])]
    return f"versus the recording: p50 {percentile(errors, 0.50):.2f}, p99 {percentile(errors, 0.99):.2f} (deg)"
