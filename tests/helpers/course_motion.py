"""The course's motions as joint targets, one command after another: each arm joint to 90°, the gripper
to 50, a batch then home; and how many 4 ms steps each command is given."""

from __future__ import annotations

STEPS_PER_COMMAND = 250  # 1 s: every move below ends and settles well within it


def home_with(position: int, angle_deg: float) -> list[float]:
    targets = [0.0] * 6
    targets[position] = angle_deg
    return targets


SCENARIOS = {
    **{f"{joint} 90": [home_with(joint, 90.0)] for joint in range(5)},
    "gripper to 50": [home_with(5, 50.0)],
    "batch -30 45 -60 30 0, then home": [[-30.0, 45.0, -60.0, 30.0, 0.0, 0.0], [0.0] * 6],
}
