"""A recording's servos identified, joint by joint: how a follower's state followed its commands.

The model, per joint, at the recording's rate (one step a frame): frame t's state is read, then its
action sent (LeRobot's order), and the joint
- acts on the action of `delay_frames` frames before (the bus, the servo's loop, the state read late);
- closes `closing` of the gap to it each frame (a first-order servo, time constant `time_constant_s`);
- turns no faster than `speed_deg_s`;
- rests `offset_deg` off its goal (gravity against a proportional servo: the sag).
Simulated open loop from the episode's first state with its actions, it is fitted to the states by a
grid over delay, closing and speed (a joint's candidates all at once, numpy), the offset from the
residual. Pure numpy: `so101 physics --fit` reads the dataset and writes the ranges
(so101.bodies.physics) centred on the fit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

MAX_DELAY_FRAMES = 12
CLOSINGS = np.geomspace(0.03, 1.0, 28)
# Speed limits tried: multiples of the fastest the joint was seen to turn in a frame, and none. Below 1: a
# follower read at 50 Hz and recorded at 30 fps has frames that span two reads, so at its limit its fastest
# frame shows it 25-35% faster than it turns.
SPEED_FACTORS = (0.55, 0.65, 0.75, 0.85, 1.0, 1.15, 1.3, 1.5, 2.0, math.inf)
# Candidates this close to the best fit as well as it (a mean error within 2%).
NEAR = 1.02
# A speed limit is claimed only where it fits 10% better than none: a smooth recording's sampling (a 50 Hz
# arm read at 30 fps) makes a limit at the fastest turn seen fit a few percent better, and it is not one.
LIMIT_NEAR = 1.10
# A joint whose commands span less than this tells nothing of its servo.
MIN_MOTION_DEG = 3.0

FloatArray = npt.NDArray[np.float64]


class FitError(ValueError):
    """A recording that cannot be fitted; one line."""


@dataclass(frozen=True)
class JointFit:
    joint: str
    delay_frames: int
    closing: float  # of the gap closed each frame
    speed_deg_s: float  # inf: never at a limit
    offset_deg: float
    error_before_deg: float  # p50 |state - action|: the state as a perfect servo would have it
    error_after_deg: float  # p50 |state - the fitted model's|
    fps: float
    mean_before_deg: float  # the same, means: a recording that mostly rests has p50s near 0 either way
    mean_after_deg: float

    @property
    def delay_s(self) -> float:
        return self.delay_frames / self.fps

    @property
    def time_constant_s(self) -> float:
        """The first-order servo's: it closes 63% of a gap in this time (0: all of it within a frame)."""
        return 0.0 if self.closing >= 1.0 else -1.0 / (self.fps * math.log(1.0 - self.closing))


def simulate(actions: FloatArray, first_state: FloatArray, delay_frames: int, closing: FloatArray,
             speed_deg_s: FloatArray, offset_deg: FloatArray, fps: float) -> FloatArray:
    """The model's states, (T, G): `actions` (T,) and the candidates' parameters (G,) each; the first is
    `first_state`."""
    steps = len(actions)
    goals = np.concatenate([np.full(delay_frames, actions[0]), actions])[:steps]
    most = np.asarray(speed_deg_s, dtype=np.float64) / fps
    state = np.broadcast_to(np.asarray(first_state, dtype=np.float64), np.shape(closing)).copy()
    states = np.empty((steps, state.size))
    for frame in range(steps):
        states[frame] = state
        state = state + np.clip((goals[frame] + offset_deg - state) * closing, -most, most)
    return states


def fit_joint(joint: str, episodes: list[tuple[FloatArray, FloatArray]], fps: float) -> JointFit:
    """One joint's servo from its episodes' (actions, states), each (T,) in degrees."""
    if not episodes or all(len(actions) < 3 for actions, _ in episodes):
        raise FitError(f"{joint}: no episode of 3 frames or more to fit")
    span = max(float(np.ptp(actions)) for actions, _ in episodes)
    if span < MIN_MOTION_DEG:
        raise FitError(f"{joint} is commanded across {span:.1f}° only: a fit needs a joint that moves "
                       f"(at least {MIN_MOTION_DEG:g}°)")
    fastest = max(float(np.abs(np.diff(states)).max()) * fps for _, states in episodes)
    coarse = _grid(CLOSINGS, [fastest * factor for factor in SPEED_FACTORS])
    # The speed rule (_best's) across every delay: a limit that fits a little better at another delay is not reached.
    by_delay = [_errors(episodes, delay, *coarse, fps) for delay in range(MAX_DELAY_FRAMES + 1)]
    least = min(float(errors.min()) for errors, _ in by_delay)
    fastest_near = max(float(coarse[1][errors <= least * LIMIT_NEAR + 1e-4].max(initial=0.0)) for errors, _ in by_delay)
    delay = int(np.argmin([np.where(coarse[1] == fastest_near, errors, np.inf).min() for errors, _ in by_delay]))
    _, delay, closing, speed, _ = _best(episodes, delay, coarse[0][coarse[1] == fastest_near],
                                        coarse[1][coarse[1] == fastest_near], fps)
    # Then finer, around the best, a frame either side of its delay: a limit a little off trades with a frame.
    speeds = [math.inf] if math.isinf(speed) else list(np.linspace(0.85 * speed, 1.15 * speed, 13))
    finer = _grid(np.geomspace(closing / 1.3, min(1.0, closing * 1.3), 15), speeds)
    _, delay, closing, speed, offset = min(_best(episodes, near_delay, *finer, fps)
                                           for near_delay in range(max(0, delay - 1), min(MAX_DELAY_FRAMES, delay + 1) + 1))
    before = np.concatenate([np.abs(states - actions) for actions, states in episodes])
    after = np.concatenate([np.abs(states - simulate(actions, states[0], delay, np.array([closing]), np.array([speed]),
                                                      np.array([offset]), fps)[:, 0]) for actions, states in episodes])
    return JointFit(joint, delay, closing, speed, offset, float(np.median(before)), float(np.median(after)), fps,
                    float(np.mean(before)), float(np.mean(after)))


def _grid(closings: npt.ArrayLike, speeds: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    closing, speed = np.meshgrid(np.asarray(closings, dtype=np.float64), np.asarray(speeds, dtype=np.float64))
    return closing.ravel(), speed.ravel()


def _errors(episodes: list[tuple[FloatArray, FloatArray]], delay: int, closing: FloatArray, speed: FloatArray,
            fps: float) -> tuple[FloatArray, FloatArray]:
    """Each candidate's mean error at `delay`, and its offset."""
    residuals = [states[:, None] - simulate(actions, states[0], delay, closing, speed, np.zeros_like(closing), fps)
                 for actions, states in episodes]
    # The offset: the residual's median once the start's transient is past (a quarter of each episode).
    offset = np.median(np.concatenate([residual[len(residual) // 4:] for residual in residuals]), axis=0)
    # The mean, not the median: a speed limit shows on the few frames of a fast move.
    return np.mean(np.abs(np.concatenate(residuals) - offset), axis=0), offset


def _best(episodes: list[tuple[FloatArray, FloatArray]], delay: int, closing: FloatArray, speed: FloatArray,
          fps: float) -> tuple[float, int, float, float, float]:
    """The best candidate at `delay`: (its mean error, delay, closing, speed, offset)."""
    errors, offset = _errors(episodes, delay, closing, speed, fps)
    # A limit the joint never reached cannot be told from none: of the candidates within 2% of the best, the fastest.
    near = errors <= errors.min() * NEAR + 1e-4
    found = int(np.argmin(np.where(near & (speed == speed[near].max()), errors, np.inf)))
    return float(errors[found]), delay, float(closing[found]), float(speed[found]), float(offset[found])


def model_errors(fit: JointFit, actions: FloatArray, states: FloatArray) -> tuple[float, float, float, float]:
    """On an episode the fit did not use: p50 |state - action| (a perfect servo), p50 |state - the model's|, and
    the two means."""
    modelled = simulate(actions, states[0], fit.delay_frames, np.array([fit.closing]), np.array([fit.speed_deg_s]),
                        np.array([fit.offset_deg]), fit.fps)[:, 0]
    before, after = np.abs(states - actions), np.abs(states - modelled)
    return float(np.median(before)), float(np.median(after)), float(np.mean(before)), float(np.mean(after))
