"""The servo model's arithmetic: PD gains from inertia, the clipped torque, the jointDamping bound.

Pure numpy, no PyBullet: `SO101Sim` feeds it the measured inertias, angles and
velocities, and the tests check it directly.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

# STS3215 servos give about 2.9-3.35 N·m; the SO-101 MuJoCo model uses forcerange ±3.35.
SERVO_TORQUE_LIMIT_NM = 3.35
DEFAULT_DAMPING_RATIO = 0.7
DEFAULT_NATURAL_FREQ_RAD_S = 20.0


def pd_gains(inertia_kg_m2: npt.ArrayLike, natural_freq_rad_s: float, damping_ratio: float) -> tuple[FloatArray, FloatArray]:
    """(Kp in N·m/rad, Kd in N·m·s/rad) per joint so that I·q̈ + Kd·q̇ + Kp·q = 0 has the given ωn and ζ.

    Scaling by each joint's inertia gives every joint the same ωn and ζ: with one
    gain for all, the light wrist would oscillate fast while the shoulder crawled.
    """
    inertia = np.asarray(inertia_kg_m2, dtype=float)
    if natural_freq_rad_s <= 0 or not np.isfinite(natural_freq_rad_s):
        raise ValueError(f"servo natural frequency must be a positive number of rad/s, got {natural_freq_rad_s!r}")
    if damping_ratio < 0 or not np.isfinite(damping_ratio):
        raise ValueError(f"servo damping ratio must be a number >= 0, got {damping_ratio!r}")
    if np.any(inertia <= 0) or not np.all(np.isfinite(inertia)):
        raise ValueError(f"inertias must be positive, got {inertia!r}")
    kp = inertia * natural_freq_rad_s**2
    kd = 2.0 * damping_ratio * inertia * natural_freq_rad_s
    return kp, kd


def pd_torque_nm(
    error_rad: npt.ArrayLike, velocity_rad_s: npt.ArrayLike, kp: npt.ArrayLike, kd: npt.ArrayLike,
    gravity_nm: npt.ArrayLike, limit_nm: npt.ArrayLike = SERVO_TORQUE_LIMIT_NM,
) -> FloatArray:
    """τ = clip(Kp·e − Kd·q̇ + gravity compensation, ±limit).

    The derivative acts on the measured velocity, not on the error, so a step in
    the goal gives no torque kick; the overshoot then comes from ζ alone.
    """
    torque = (
        np.asarray(kp, dtype=np.float64) * np.asarray(error_rad, dtype=np.float64)
        - np.asarray(kd, dtype=np.float64) * np.asarray(velocity_rad_s, dtype=np.float64)
        + np.asarray(gravity_nm, dtype=np.float64)
    )
    limit = np.asarray(limit_nm, dtype=np.float64)
    return np.clip(torque, -limit, limit)


def joint_damping_stable(damping_n_m_s: float, time_step_s: float, inertia_kg_m2: float) -> bool:
    """Whether PyBullet's explicit `jointDamping` c is stable: c·dt/I < 2.

    Each step subtracts c·q̇·dt/I from q̇; past 2 the velocity flips sign and grows.
    """
    return damping_n_m_s * time_step_s / inertia_kg_m2 < 2.0
