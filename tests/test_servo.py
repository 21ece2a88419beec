"""Exercise 2 made true: the servo arithmetic, step-response numbers, and the two control modes in PyBullet."""

from __future__ import annotations

import math

import numpy as np
import pytest

from so101.bodies.pd_servo import SERVO_TORQUE_LIMIT_NM, joint_damping_stable, pd_gains, pd_torque_nm
from so101.step_response import overshoot_percent, settling_time_s, step_metrics

pytestmark = pytest.mark.slow  # steps PyBullet through step responses: not in the fast subset

TIME_STEP_S = 0.004
# Measured with `so101 plot-step` (joint 0, 0° -> 90°, ωn = 20 rad/s): ζ = 0.7 settles
# into the 2% band after 0.31 s; the bound leaves room for another PyBullet build.
SERVO_SETTLING_BOUND_S = 0.4


# -- pure arithmetic -----------------------------------------------------------------------
def test_gains_give_each_joint_the_same_natural_frequency_and_damping_ratio():
    kp, kd = pd_gains([0.01, 7e-5], natural_freq_rad_s=20.0, damping_ratio=0.7)
    assert kp == pytest.approx([4.0, 0.028])
    assert kd == pytest.approx([0.28, 0.00196])
    inertia = np.array([0.01, 7e-5])
    assert np.sqrt(kp / inertia) == pytest.approx([20.0, 20.0])
    assert kd / (2 * np.sqrt(kp * inertia)) == pytest.approx([0.7, 0.7])


@pytest.mark.parametrize(
    "inertias, freq, zeta, message",
    [([0.01], 20.0, -0.1, "damping ratio"), ([0.01], 0.0, 0.7, "natural frequency"), ([0.0], 20.0, 0.7, "inertias")],
)
def test_gains_reject_impossible_values(inertias, freq, zeta, message):
    with pytest.raises(ValueError, match=message):
        pd_gains(inertias, freq, zeta)


def test_torque_is_pd_plus_gravity_and_clipped_to_the_limit():
    torque = pd_torque_nm(
        error_rad=[0.1, 2.0, -2.0], velocity_rad_s=[1.0, 0.0, 0.0], kp=[4.0, 4.0, 4.0], kd=[0.28] * 3,
        gravity_nm=[0.5, 0.0, 0.0],
    )
    assert torque == pytest.approx([4.0 * 0.1 - 0.28 * 1.0 + 0.5, SERVO_TORQUE_LIMIT_NM, -SERVO_TORQUE_LIMIT_NM])


def test_joint_damping_bound_is_c_dt_over_inertia_below_two():
    # wrist_roll's effective inertia, 7e-5 kg·m², at the 4 ms step: c = 0.035 is the edge.
    assert joint_damping_stable(0.02, TIME_STEP_S, 7e-5)
    assert not joint_damping_stable(0.035, TIME_STEP_S, 7e-5)
    assert not joint_damping_stable(0.2, TIME_STEP_S, 7e-5)
    # The same c on shoulder_pan (1.6e-2 kg·m²) is far from the edge.
    assert joint_damping_stable(0.2, TIME_STEP_S, 1.6e-2)


def test_overshoot_and_settling_of_a_hand_made_series():
    times = [0.0, 0.1, 0.2, 0.3, 0.4, 0.5]
    angles = [0.0, 50.0, 110.0, 97.0, 101.0, 100.0]
    assert overshoot_percent(angles, 0.0, 100.0) == pytest.approx(10.0)
    # 97 is outside the ±2 band, 101 is the first sample of the last stretch inside.
    assert settling_time_s(times, angles, 0.0, 100.0) == pytest.approx(0.4)
    assert settling_time_s(times, [0, 50, 90, 95, 97, 96], 0.0, 100.0) is None
    assert overshoot_percent([0, 50, 90, 99], 0.0, 100.0) == 0.0


def test_a_step_down_is_measured_the_same_way():
    assert overshoot_percent([90.0, 40.0, -15.0, 0.0], 90.0, 0.0) == pytest.approx(100 * 15 / 90)
    assert overshoot_percent([90.0, 40.0, 5.0, 0.0], 90.0, 0.0) == 0.0


def test_metrics_of_an_ideal_second_order_response_match_the_textbook():
    zeta, natural_freq = 0.2, 20.0
    damped_freq = natural_freq * math.sqrt(1 - zeta**2)
    times = np.arange(0, 3, 1e-4)
    response = 1 - np.exp(-zeta * natural_freq * times) * (
        np.cos(damped_freq * times) + zeta / math.sqrt(1 - zeta**2) * np.sin(damped_freq * times)
    )
    metrics = step_metrics(times, 90 * response, 0.0, 90.0)
    assert metrics.overshoot_percent == pytest.approx(100 * math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2)), abs=0.05)
    # The envelope bound 4/(ζωn) = 1 s is an upper estimate of the 2% settling time.
    assert 0.7 < metrics.settling_time_s <= 1.0


def test_a_step_must_move():
    with pytest.raises(ValueError, match="different from the start"):
        overshoot_percent([0.0, 0.0], 0.0, 0.0)


# -- the two control modes in PyBullet ----------------------------------------------------
def step_joint(sim, joint: int, target_deg: float, duration_s: float = 1.5):
    goal = [0.0] * 6
    goal[joint] = target_deg
    sim.set_targets_deg(goal)
    times, angles, largest_torque = [0.0], [float(sim.joint_angles_deg()[joint])], 0.0
    for _ in range(round(duration_s / sim.time_step_s)):
        sim.step()
        times.append(sim.sim_time_s)
        angles.append(float(sim.joint_angles_deg()[joint]))
        largest_torque = max(largest_torque, float(np.abs(sim.last_torques_nm).max()))
    return step_metrics(times, angles, 0.0, target_deg), largest_torque


@pytest.mark.parametrize("link_damping", [None, 0.0, 0.2])
def test_position_mode_never_overshoots_with_or_without_link_damping(make_sim, link_damping):
    sim = make_sim(time_step_s=TIME_STEP_S, link_damping=link_damping)
    metrics, _ = step_joint(sim, 0, 90.0)
    assert metrics.overshoot_percent < 1.0
    assert abs(metrics.final_error_deg) < 0.5


def test_servo_with_low_damping_overshoots_clearly(make_sim):
    sim = make_sim(time_step_s=TIME_STEP_S, control_mode="servo", servo_damping_ratio=0.2)
    metrics, _ = step_joint(sim, 0, 90.0)
    assert metrics.overshoot_percent > 10.0


def test_servo_with_damping_ratio_0_7_settles_and_reaches_the_target(make_sim):
    sim = make_sim(time_step_s=TIME_STEP_S, control_mode="servo", servo_damping_ratio=0.7)
    metrics, largest_torque = step_joint(sim, 0, 90.0)
    assert metrics.overshoot_percent < 5.0
    assert metrics.settling_time_s is not None and metrics.settling_time_s < SERVO_SETTLING_BOUND_S
    assert abs(metrics.final_error_deg) < 1.0
    assert largest_torque == pytest.approx(SERVO_TORQUE_LIMIT_NM)  # a 90° step saturates at first


@pytest.mark.parametrize("limit_nm", [SERVO_TORQUE_LIMIT_NM, 1.0])
def test_servo_torque_never_exceeds_the_limit(make_sim, limit_nm):
    sim = make_sim(time_step_s=TIME_STEP_S, control_mode="servo", servo_damping_ratio=0.1, servo_torque_limit_nm=limit_nm)
    _, largest_torque = step_joint(sim, 0, -90.0, duration_s=1.0)
    assert largest_torque <= limit_nm + 1e-12
    assert largest_torque == pytest.approx(limit_nm)


def test_servo_holds_the_arm_against_gravity_and_reaches_a_pose(make_sim):
    sim = make_sim(time_step_s=TIME_STEP_S, control_mode="servo")
    sim.step(250)
    assert np.abs(sim.joint_angles_deg()).max() < 0.5
    pose_deg = [30.0, -40.0, 50.0, 20.0, 60.0, 20.0]
    sim.set_targets_deg(pose_deg)
    sim.step(375)
    assert sim.joint_angles_deg() == pytest.approx(pose_deg, abs=1.0)


def test_effective_inertias_are_the_mass_matrix_diagonal_measured_here(shared_sim):
    inertias = shared_sim.effective_inertias_kg_m2([0.0] * 6)
    # At home, measured: shoulder_pan 1.56e-2, wrist_roll 6.9e-5, gripper 2.1e-5 kg·m².
    assert inertias[0] == pytest.approx(1.56e-2, rel=0.02)
    assert inertias[4] == pytest.approx(6.9e-5, rel=0.02)
    assert inertias[5] == pytest.approx(2.1e-5, rel=0.02)


def test_unknown_control_mode_is_refused_with_the_accepted_ones(make_sim):
    with pytest.raises(ValueError, match="unknown control mode 'torque'; use one of: position, servo"):
        make_sim(control_mode="torque")
