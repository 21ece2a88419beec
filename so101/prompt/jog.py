"""Key jogging, the course's mini project 7: what each key does to the arm's targets. Pure:
no terminal and no dora (the prompt reads the keys and sends what `press` returns).

Joint mode: each press moves one joint by the step; W raises the upper arm, A turns the arm
left (in the URDF a positive shoulder_lift lowers the arm and a positive shoulder_pan turns it
right, seen from behind: `so101.kinematics` confirms both). Cartesian mode: W/S, A/D and R/F
move the gripper tip up/down, left/right and forward/back in the base frame, and the arm
follows by inverse kinematics. Targets never leave the joint limits; a press that would is
clamped, and the note says which joint is at its limit.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Sequence

from so101.robot import ACTUATED_JOINTS, GRIPPER_COMMAND_INDEX, NUM_ARM_JOINTS

# key: (joint index, direction of the angle)
JOINT_KEYS = {
    "w": (1, -1), "s": (1, +1),   # shoulder_lift: raise / lower the upper arm
    "a": (0, -1), "d": (0, +1),   # shoulder_pan: turn left / right
    "r": (2, -1), "f": (2, +1),   # elbow_flex: raise / lower the forearm
    "t": (3, -1), "g": (3, +1),   # wrist_flex: tip up / down
    "z": (4, -1), "x": (4, +1),   # wrist_roll
    "o": (5, +1), "c": (5, -1),   # gripper: open / close
}
# Cartesian mode: key: (axis of the base frame, direction); x forward, y left, z up.
CARTESIAN_KEYS = {"w": (2, +1), "s": (2, -1), "a": (1, +1), "d": (1, -1), "r": (0, +1), "f": (0, -1)}
STEPS_DEG = (0.5, 1.0, 2.0, 5.0, 10.0)
STEPS_MM = (1.0, 2.0, 5.0, 10.0, 20.0)
DEFAULT_STEP = 2  # 2° or 5 mm
# A Cartesian step that IK can only reach by swinging a joint this far is not sent: it would be
# a jump to another branch of the solution, not a step.
MAX_IK_SWING_DEG = 20.0
EXIT_KEYS = ("esc", "q")
# Starts an episode (the last `record` task) or stops and saves it, with `so101 teleop --record`.
EPISODE_KEY = "e"

# Each language's texts: one format string per key, and the key map as a list of lines.
TEXT: dict[str, dict[str, Any]] = {
    "zh": {
        "map": [
            "  点动模式(按键即动,按住连续动):",
            "    W/S 大臂抬起/放下   A/D 向左/向右转   R/F 小臂抬起/放下   T/G 手腕上/下",
            "    Z/X 手腕旋转        O/C 夹爪张开/闭合",
            "    笛卡尔模式(Tab 切换):W/S 末端上/下  A/D 左/右  R/F 前/后(毫米,基座坐标系)",
            "    - / + 步长变细/变粗   H 回零   空格 停在当前位置   M 或 ? 显示按键   Esc 或 q 返回命令行",
            "    E 开始/结束录制一段(so101 teleop --record;任务用上次 record 的描述)",
        ],
        "joint_mode": "关节",
        "cartesian_mode": "笛卡尔",
        "status": "[{mode}] 步长 {step}  {angles}",
        "tip": "  末端 ({x:.0f}, {y:.0f}, {z:.0f}) mm",
        "limit": "{name} 已到限位 {limit:.1f}°",
        "unreachable": "够不到 ({x:.0f}, {y:.0f}, {z:.0f}) mm",
        "swing": "该步需要 {name} 转动 {swing:.0f}°,未发送",
        "held": "停在当前位置",
        "home": "回零",
        "unknown_key": "按键 {key!r} 没有功能(M 显示按键)",
        "no_kinematics": "笛卡尔模式不可用: {error}",
    },
    "en": {
        "map": [
            "  jog mode (a press moves, holding repeats):",
            "    W/S raise/lower the arm   A/D turn left/right   R/F raise/lower the forearm   T/G wrist up/down",
            "    Z/X wrist roll            O/C open/close the gripper",
            "    Cartesian (Tab switches): W/S tip up/down  A/D left/right  R/F forward/back (mm, base frame)",
            "    -/+ finer/coarser step   H home   Space hold here   M or ? this map   Esc or q back to the prompt",
            "    E start/stop an episode (so101 teleop --record; the task of the last `record`)",
        ],
        "joint_mode": "joint",
        "cartesian_mode": "cartesian",
        "status": "[{mode}] step {step}  {angles}",
        "tip": "  tip ({x:.0f}, {y:.0f}, {z:.0f}) mm",
        "limit": "{name} at its limit {limit:.1f}°",
        "unreachable": "out of reach: ({x:.0f}, {y:.0f}, {z:.0f}) mm",
        "swing": "that step needs {name} to swing {swing:.0f}°: not sent",
        "held": "holding here",
        "home": "home",
        "unknown_key": "key {key!r} does nothing (M shows the keys)",
        "no_kinematics": "Cartesian mode is not available: {error}",
    },
}
SHORT_NAMES = ("pan", "lift", "elbow", "wrist", "roll", "grip")


@dataclass(frozen=True)
class Jog:
    """Where jogging stands: the six targets (degrees), the step, the mode, the last note."""

    targets_deg: tuple[float, ...]
    step_index: int = DEFAULT_STEP
    cartesian: bool = False
    note: str = ""

    @property
    def step_deg(self) -> float:
        return STEPS_DEG[self.step_index]

    @property
    def step_mm(self) -> float:
        return STEPS_MM[self.step_index]


@dataclass(frozen=True)
class Pressed:
    jog: Jog
    send_deg: tuple[float, ...] | None = None  # the joint_cmd to send (six angles), or None
    show_map: bool = False
    leave: bool = False


def _clamped(index: int, angle_deg: float, text: dict) -> tuple[float, str]:
    joint = ACTUATED_JOINTS[index]
    clamped = joint.clamp_deg(angle_deg)
    if clamped != angle_deg:
        return clamped, text["limit"].format(name=joint.name, limit=clamped)
    return clamped, ""


def press(jog: Jog, key: str, state_deg: Sequence[float] | None, kinematics, lang: str = "en") -> Pressed:
    """One key press. `state_deg` is the arm's latest six angles (for Space); `kinematics` an
    so101.kinematics.Kinematics for Cartesian mode (or an exception saying why there is none)."""
    text = TEXT[lang]
    key = key.lower() if len(key) == 1 else key
    if key in EXIT_KEYS:
        return Pressed(replace(jog, note=""), leave=True)
    if key in ("m", "?"):
        return Pressed(replace(jog, note=""), show_map=True)
    if key in ("-", "_"):
        return Pressed(replace(jog, step_index=max(jog.step_index - 1, 0), note=""))
    if key in ("+", "="):
        return Pressed(replace(jog, step_index=min(jog.step_index + 1, len(STEPS_DEG) - 1), note=""))
    if key == "tab":
        if isinstance(kinematics, Exception):
            return Pressed(replace(jog, note=text["no_kinematics"].format(error=kinematics)))
        return Pressed(replace(jog, cartesian=not jog.cartesian, note=""))
    if key == "h":
        targets = (0.0,) * NUM_ARM_JOINTS + jog.targets_deg[GRIPPER_COMMAND_INDEX:]
        return Pressed(replace(jog, targets_deg=targets, note=text["home"]), send_deg=targets)
    if key == "space":
        targets = tuple(state_deg) if state_deg is not None else jog.targets_deg
        return Pressed(replace(jog, targets_deg=targets, note=text["held"]), send_deg=targets)
    if jog.cartesian and key in CARTESIAN_KEYS:
        return _cartesian(jog, key, kinematics, text)
    if key in JOINT_KEYS:
        index, direction = JOINT_KEYS[key]
        angle, note = _clamped(index, jog.targets_deg[index] + direction * jog.step_deg, text)
        if angle == jog.targets_deg[index]:
            return Pressed(replace(jog, note=note))
        targets = tuple(angle if i == index else value for i, value in enumerate(jog.targets_deg))
        return Pressed(replace(jog, targets_deg=targets, note=note), send_deg=targets)
    return Pressed(replace(jog, note=text["unknown_key"].format(key=key)))


def _cartesian(jog: Jog, key: str, kinematics, text: dict) -> Pressed:
    axis, direction = CARTESIAN_KEYS[key]
    arm_deg = jog.targets_deg[:NUM_ARM_JOINTS]
    target_mm = list(kinematics.tip_mm(arm_deg))
    target_mm[axis] += direction * jog.step_mm
    reach = kinematics.solve(target_mm, seed_deg=arm_deg)
    if not reach.reachable:
        x, y, z = target_mm
        return Pressed(replace(jog, note=text["unreachable"].format(x=x, y=y, z=z)))
    swings = [abs(new - old) for new, old in zip(reach.joints_deg, arm_deg)]
    if max(swings) > MAX_IK_SWING_DEG:
        index = swings.index(max(swings))
        return Pressed(replace(jog, note=text["swing"].format(name=ACTUATED_JOINTS[index].name, swing=max(swings))))
    targets = tuple(reach.joints_deg) + jog.targets_deg[NUM_ARM_JOINTS:]
    return Pressed(replace(jog, targets_deg=targets, note=""), send_deg=targets)


def status_line(jog: Jog, state_deg: Sequence[float] | None, tip_mm, lang: str = "en") -> str:
    """The one line redrawn in place: mode, step, the arm's angles now, the tip in Cartesian mode, the note."""
    text = TEXT[lang]
    shown = state_deg if state_deg is not None else jog.targets_deg
    # round(...) + 0.0: a joint a hair below zero shows 0.0, not -0.0
    angles = " ".join(f"{name} {round(angle, 1) + 0.0:.1f}" for name, angle in zip(SHORT_NAMES, shown))
    step = f"{jog.step_mm:g} mm" if jog.cartesian else f"{jog.step_deg:g}°"
    line = text["status"].format(mode=text["cartesian_mode" if jog.cartesian else "joint_mode"], step=step, angles=angles)
    if jog.cartesian and tip_mm is not None:
        x, y, z = (round(value) + 0.0 for value in tip_mm)
        line += text["tip"].format(x=x, y=y, z=z)
    if jog.note:
        line += "  | " + jog.note
    return line
