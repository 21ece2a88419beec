"""`so101 plot-step`: the step response of one joint for a few damping values, as a PNG and a table.

Course exercise 2, measured. In PyBullet's position mode the damping values are the
course's link damping (`changeDynamics(linearDamping=c, angularDamping=c)`); in its servo
mode they are the PD servo's damping ratio ζ. With `--body mujoco` they are the joints'
own damping in N·m·s/rad, the MJCF's 0.60 first: the exercise as the course means it.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from so101.runtime import argtypes
from so101.bodies.registry import DEFAULT_BODY, SIMULATED_BODIES
from so101.runtime.dataflow import TICK_PERIOD_S
from so101.robot import ACTUATED_JOINTS, HOME_POSE_DEG
from so101.bodies.pd_servo import DEFAULT_NATURAL_FREQ_RAD_S, SERVO_TORQUE_LIMIT_NM
from so101.step_response import SETTLING_BAND, StepMetrics, step_metrics

# Keyed by what is stepped: PyBullet's two control modes, or the MuJoCo body.
DEFAULT_DAMPING = {"servo": (0.1, 0.2, 0.7), "position": (0.0, 0.2), "mujoco": (0.6, 0.3, 0.0)}
DAMPING_LABEL = {"servo": "ζ", "position": "link damping", "mujoco": "joint damping"}
MAX_DURATION_S = 60.0
MISSED_TARGET_DEG = 2.0


@dataclass(frozen=True)
class StepRun:
    damping: float
    times_s: np.ndarray
    angles_deg: np.ndarray
    max_abs_torque_nm: float
    metrics: StepMetrics


def _joint(text: str) -> int:
    if text not in {str(i) for i in range(len(ACTUATED_JOINTS))}:
        raise argparse.ArgumentTypeError(f"{text!r} is not a joint number: use 0-4 for the arm, 5 for the gripper")
    return int(text)


_non_negative = argtypes.number(lambda value: value >= 0, "a damping value: use numbers >= 0")
_duration = argtypes.number(lambda value: 0 < value <= MAX_DURATION_S,
                            f"a duration: use seconds, more than 0 and at most {MAX_DURATION_S:g}")


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    parser.add_argument(
        "--body", choices=SIMULATED_BODIES, default=DEFAULT_BODY,
        help="pybullet (default; --mode applies) or mujoco: the MJCF's servos, damping = joint damping in N·m·s/rad",
    )
    parser.add_argument("--joint", type=_joint, default=0, help="joint to step: 0-4 arm, 5 gripper (default 0, as in exercise 2)")
    parser.add_argument("--target", type=float, default=90.0, metavar="DEG", help="target angle in degrees (default 90)")
    parser.add_argument(
        "--mode", choices=("position", "servo"), default="servo",
        help="PyBullet only. servo (default): PD torque servo, damping = ζ; position: the course's "
        "POSITION_CONTROL, damping = the course's link damping",
    )
    parser.add_argument(
        "--damping", type=_non_negative, nargs="+", metavar="VALUE", default=None,
        help="one line per value (default: ζ = 0.1 0.2 0.7 in servo mode; link damping 0 0.2 in position mode; "
        "joint damping 0.6 0.3 0 N·m·s/rad in MuJoCo)",
    )
    parser.add_argument("--duration", type=_duration, default=1.5, help="simulated seconds after the step (default 1.5)")
    parser.add_argument(
        "--out", type=Path, default=Path("out/step_response.png"), help="PNG to write (default out/step_response.png)",
    )


def _simulator(kind: str, damping: float):
    if kind == "mujoco":
        from so101.bodies.mujoco_sim import SO101MuJoCo

        return SO101MuJoCo(mode="direct", time_step_s=TICK_PERIOD_S, joint_damping_n_m_s=damping, renders=False,
                           log=lambda message: None)
    from so101.bodies.pybullet_sim import SO101Sim

    if kind == "servo":
        return SO101Sim(mode="direct", time_step_s=TICK_PERIOD_S, control_mode=kind, log=lambda message: None,
                        servo_damping_ratio=damping)
    return SO101Sim(mode="direct", time_step_s=TICK_PERIOD_S, control_mode=kind, log=lambda message: None,
                    link_damping=damping)


def record_step(joint: int, target_deg: float, kind: str, damping: float, duration_s: float) -> StepRun:
    """Start at home, set one joint's goal to target_deg, record its angle every 4 ms step.

    kind: "position" or "servo" (PyBullet's control modes) or "mujoco"."""
    with _simulator(kind, damping) as sim:
        start_deg = float(sim.joint_angles_deg()[joint])
        goal_deg = list(HOME_POSE_DEG)
        goal_deg[joint] = target_deg
        sim.set_targets_deg(goal_deg)
        count = round(duration_s / TICK_PERIOD_S)
        times_s = np.zeros(count + 1)
        angles_deg = np.zeros(count + 1)
        angles_deg[0] = start_deg
        max_torque = 0.0
        for i in range(1, count + 1):
            sim.step()
            times_s[i] = sim.sim_time_s
            angles_deg[i] = sim.joint_angles_deg()[joint]
            if kind == "servo":
                max_torque = max(max_torque, float(np.abs(sim.last_torques_nm).max()))
    return StepRun(damping, times_s, angles_deg, max_torque, step_metrics(times_s, angles_deg, start_deg, target_deg))


def _settling_text(seconds: float | None) -> str:
    return "never" if seconds is None else f"{seconds:.2f} s"


def format_table(runs: list[StepRun], mode: str) -> str:
    label = DAMPING_LABEL[mode]
    lines = [f"  {label:>12}   overshoot   2% settling   final error"]
    for run in runs:
        m = run.metrics
        lines.append(
            f"  {run.damping:>12g}   {m.overshoot_percent:7.1f} %   {_settling_text(m.settling_time_s):>11}   "
            f"{m.final_error_deg:+9.2f}°"
        )
    return "\n".join(lines)


def _mode_description(mode: str) -> str:
    if mode == "mujoco":
        return "MuJoCo: the MJCF's position servos, kp 17.8 N·m/rad, ±3.35 N·m; damping in N·m·s/rad"
    if mode == "servo":
        return (
            f"servo mode: PD torque, ωn = {DEFAULT_NATURAL_FREQ_RAD_S:g} rad/s, "
            f"torque limit ±{SERVO_TORQUE_LIMIT_NM:g} N·m"
        )
    return "position mode: the course's POSITION_CONTROL, maxVelocity 3 rad/s"


def write_plot(runs: list[StepRun], joint: int, start_deg: float, target_deg: float, mode: str, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(figsize=(8, 4.8), dpi=100)
    band_deg = SETTLING_BAND * abs(target_deg - start_deg)
    axes.axhspan(target_deg - band_deg, target_deg + band_deg, color="0.85", label="target ±2% (settling band)")
    axes.axhline(target_deg, color="0.4", linewidth=0.8, linestyle="--")
    # Different dashes, so that lines lying on top of each other (position mode) stay visible.
    line_styles = ("-", "--", ":", "-.")
    for number, run in enumerate(runs):
        m = run.metrics
        axes.plot(
            run.times_s, run.angles_deg, linewidth=1.8, linestyle=line_styles[number % len(line_styles)],
            label=f"{DAMPING_LABEL[mode]} = {run.damping:g}: overshoot {m.overshoot_percent:.1f}%, "
            + ("does not settle in this run" if m.settling_time_s is None else f"settles in {m.settling_time_s:.2f} s"),
        )
    joint_info = ACTUATED_JOINTS[joint]
    axes.set_title(
        f"Step response of joint {joint} ({joint_info.name}): {start_deg:g}° → {target_deg:g}°\n{_mode_description(mode)}",
        fontsize=11,
    )
    axes.set_xlabel("time after the step (s)")
    axes.set_ylabel("joint angle (°)")
    axes.grid(True, alpha=0.3)
    axes.legend(loc="lower right", fontsize=9)
    figure.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out)
    plt.close(figure)


def run(args: argparse.Namespace) -> int:
    joint = ACTUATED_JOINTS[args.joint]
    if not joint.allows_deg(args.target):
        print(f"so101 plot-step: --target {args.target:g}° is outside joint {args.joint} ({joint.name})'s range "
              f"{joint.limits_text()}", file=sys.stderr)
        return 2
    start_deg = HOME_POSE_DEG[args.joint]
    if args.target == start_deg:
        print(f"so101 plot-step: --target must differ from the start angle {start_deg:g}° to make a step", file=sys.stderr)
        return 2
    kind = "mujoco" if args.body == "mujoco" else args.mode
    damping_values = args.damping if args.damping is not None else DEFAULT_DAMPING[kind]
    runs = [record_step(args.joint, args.target, kind, value, args.duration) for value in damping_values]
    write_plot(runs, args.joint, start_deg, args.target, kind, args.out)
    print(
        f"step response: joint {args.joint} ({joint.name}) {start_deg:g}° -> {args.target:g}°, "
        f"{_mode_description(kind)}, {TICK_PERIOD_S * 1000:g} ms steps, {args.duration:g} s"
    )
    print(format_table(runs, kind))
    if kind == "servo":
        print(f"largest torque sent: {max(run.max_abs_torque_nm for run in runs):.2f} N·m")
    far = [run for run in runs if abs(run.metrics.final_error_deg) > MISSED_TARGET_DEG]
    # In the last 0.1 s a swinging joint still moves; one held by the ground or itself does not.
    swinging = [run for run in far if np.ptp(run.angles_deg[-round(0.1 / TICK_PERIOD_S):]) > 0.5]
    if swinging:
        print(
            f"note: with {DAMPING_LABEL[kind]} {', '.join(f'{run.damping:g}' for run in swinging)} the joint is still "
            "swinging at the end; a longer --duration shows where it settles"
        )
    if len(far) > len(swinging):
        print(
            "note: the joint ended more than 2° from the target: gravity holds a soft servo off it, "
            "or the arm touches the ground or itself"
        )
    print(f"wrote {args.out}")
    return 0
