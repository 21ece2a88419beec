"""Step-response numbers from a time series: overshoot % and 2% settling time.

Pure numpy; `so101 plot-step` records the series in PyBullet and hands them here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SETTLING_BAND = 0.02


@dataclass(frozen=True)
class StepMetrics:
    overshoot_percent: float
    settling_time_s: float | None  # None: still outside the band at the end of the series
    final_error_deg: float


def overshoot_percent(angles_deg, start_deg: float, target_deg: float) -> float:
    """How far past the target the response went, in % of the step size; 0 if it never passed it."""
    step = target_deg - start_deg
    if step == 0:
        raise ValueError("a step response needs a target different from the start angle")
    angles = np.asarray(angles_deg, dtype=float)
    # Measured in the direction of the step, so a step down works the same way.
    beyond = (angles - target_deg) * np.sign(step)
    return max(0.0, float(beyond.max()) / abs(step) * 100.0)


def settling_time_s(times_s, angles_deg, start_deg: float, target_deg: float, band: float = SETTLING_BAND) -> float | None:
    """The time after which the response stays within band·|step| of the target; None if it never does."""
    step = target_deg - start_deg
    if step == 0:
        raise ValueError("a step response needs a target different from the start angle")
    times = np.asarray(times_s, dtype=float)
    angles = np.asarray(angles_deg, dtype=float)
    if times.shape != angles.shape or times.size == 0:
        raise ValueError("times and angles must be two series of the same, non-zero length")
    outside = np.abs(angles - target_deg) > band * abs(step)
    if outside[-1]:
        return None
    if not outside.any():
        return float(times[0])
    last_outside = int(np.flatnonzero(outside)[-1])
    return float(times[last_outside + 1])


def step_metrics(times_s, angles_deg, start_deg: float, target_deg: float) -> StepMetrics:
    return StepMetrics(
        overshoot_percent=overshoot_percent(angles_deg, start_deg, target_deg),
        settling_time_s=settling_time_s(times_s, angles_deg, start_deg, target_deg),
        final_error_deg=float(np.asarray(angles_deg, dtype=float)[-1] - target_deg),
    )
