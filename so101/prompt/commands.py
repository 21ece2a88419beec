"""The keyboard prompt's command language, as a pure parser: a typed line -> a command or an error.

Commands (course step D and exercise 1, plus the gripper):
  J ANGLE                  one joint: J is 0-4 for the arm, 5 for the gripper; ANGLE in degrees
  batch a0 a1 a2 a3 a4 [g] all five arm joints at once, optionally the gripper as a sixth value
  grip ANGLE | open | close
  home | list | state | save NAME | go NAME | poses | snapshot [FILE] | help | quit | exit
Beyond the course (its mini project 7, and Cartesian targets):
  xyz X Y Z                the gripper tip to that point: millimetres, in the arm's base frame
  where                    where the tip is now (forward kinematics of joint_state)
  jog                      key jogging (so101/prompt/jog.py)
Episodes, with `so101 teleop --record DIR` (the recorder node answers):
  record TASK TEXT | stop | discard | episodes
A task's scene, with `so101 teleop --task NAME` (the body answers):
  reset [SEED] | task | expert     (the scripted expert does the task once; a typed command takes over)
A trained policy, with `so101 teleop --policy DIR` (the policy node answers):
  policy on | policy off           (it drives from the newest state; a typed command takes over)

Out-of-limit angles are refused, not clamped: at a keyboard a value beyond the
URDF limits is far more likely a typo (900 for 90) than a wish for the limit.
All reply texts, in Chinese (the course) and English, live here too, so
so101/prompt/control.py only decides what to send and which text to print.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from so101.robot import ACTUATED_JOINTS, GRIPPER, GRIPPER_COMMAND_INDEX, NUM_ARM_JOINTS

# The gripper's jaw: 0° closes it, 100° (the URDF's upper limit, 1.74533 rad, rounded down) opens it fully.
GRIPPER_CLOSED_DEG = 0.0
GRIPPER_OPEN_DEG = float(math.floor(GRIPPER.upper_deg))

MAX_POSE_NAME_CHARS = 40

# Plain decimal numbers only: Python's float() would also take "nan", "inf" and "1_0".
_NUMBER = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$")
# Spaces or commas (ASCII or full-width) separate words: "batch -30,45,-60,30,0" works too.
_SEPARATORS = re.compile(r"[\s,,]+")


@dataclass(frozen=True)
class SetJoint:
    index: int  # 0-4 arm, 5 gripper
    angle_deg: float


@dataclass(frozen=True)
class Batch:
    angles_deg: tuple[float, ...]  # five arm angles, or five + the gripper


@dataclass(frozen=True)
class Home:
    pass


@dataclass(frozen=True)
class ListJoints:
    pass


@dataclass(frozen=True)
class ShowState:
    """Print the latest joint_state: headless, the way to see where the arm is."""


@dataclass(frozen=True)
class SavePose:
    name: str


@dataclass(frozen=True)
class GoPose:
    name: str


@dataclass(frozen=True)
class ListPoses:
    pass


@dataclass(frozen=True)
class Snapshot:
    """A PNG of the arm as it is now (from joint_state), drawn headless."""

    path: str = "out/snapshot.png"


@dataclass(frozen=True)
class MoveTip:
    """`xyz X Y Z`: the gripper tip to a point in the base frame, millimetres."""

    target_mm: tuple[float, float, float]


@dataclass(frozen=True)
class Where:
    pass


@dataclass(frozen=True)
class JogKeys:
    pass


@dataclass(frozen=True)
class Episodes:
    """A recorder command: `record TASK TEXT`, `stop`, `discard` or `episodes` (so101.dataset.recording)."""

    command: str
    task: str = ""


@dataclass(frozen=True)
class ResetTask:
    """`reset [SEED]`: the task's scene laid out again (from SEED, or the next seed) and the arm homed."""

    seed: int | None = None


@dataclass(frozen=True)
class ShowTask:
    """`task`: the task, its seed's layout, where the cube is now, and whether it is in the box."""


@dataclass(frozen=True)
class RunExpert:
    """`expert`: the task's scripted expert performs it once from where things are; a typed command takes over."""


@dataclass(frozen=True)
class RunPolicy:
    """`policy on` / `policy off`: a trained policy drives from the newest state, or stops; a typed command takes over."""

    word: str  # "on" or "off"


@dataclass(frozen=True)
class Help:
    pass


@dataclass(frozen=True)
class Quit:
    pass


@dataclass(frozen=True)
class Empty:
    """A blank line: nothing to do."""


@dataclass(frozen=True)
class ParseError:
    message: str  # one line, already in the prompt's language, saying what is accepted


Command = (
    SetJoint | Batch | Home | ListJoints | ShowState | SavePose | GoPose | ListPoses | Snapshot | MoveTip | Where | JogKeys
    | Episodes | ResetTask | ShowTask | RunExpert | RunPolicy | Help | Quit | Empty
)


TEXT = {
    "zh": {
        "title": "  SO-101 键盘控制",
        "poses_file": "  姿态文件: {path}(已保存 {count} 个)",
        "stopped": "  数据流已停止,退出",
        "joint_line": "    {index}: {name} ({label})",
        "sent_joint": "  → 关节 {index} ({name}) → {angle}°",
        "sent_batch": "  → 全关节 → {angles}°",
        "sent_batch_gripper": "  → 全关节 → {angles}°,夹爪 → {gripper}°",
        "sent_home": "  → 回零指令已发送",
        "saved": "  → 姿态 '{name}' 已保存: {angles}°",
        "saved_gripper": "  → 姿态 '{name}' 已保存: {angles}°,夹爪 {gripper}°",
        "saved_not_persisted": "  → 姿态 '{name}' 已保存(仅本次运行有效,写文件失败: {error})",
        "no_state": "  还没有收到 joint_state(仿真节点在运行吗?),无法保存姿态",
        "state": "  当前关节角度: {angles}°",
        "state_gripper": "  当前关节角度: {angles}°,夹爪 {gripper}°",
        "no_state_yet": "  还没有收到 joint_state(仿真节点在运行吗?)",
        "go": "  → 移动到姿态 '{name}'",
        "unknown_pose": "  未找到姿态 '{name}';已保存的姿态: {known}(用 'save 名字' 保存)",
        "no_poses": "  还没有保存的姿态(用 'save 名字' 保存当前姿态)",
        "pose_line": "    {name}: {angles}°",
        "pose_line_gripper": "    {name}: {angles}°,夹爪 {gripper}°",
        "none": "无",
        "bye": "  再见",
        "unknown": "  无法识别 '{text}':可用 '关节号 角度'(如 '0 45')、batch、grip、open、close、home、list、"
        "state、save、go、poses、snapshot、xyz、where、jog、record、stop、discard、episodes、reset、task、expert、policy、help、quit(输入 help 查看)",
        "joint_form": "  格式错误:关节号 角度(如 '0 45'),关节号 0-5(5 = 夹爪)",
        "joint_range": "  关节号范围 0-5(0-4 手臂,5 夹爪),收到 '{text}';格式:关节号 角度(如 '0 45')",
        "bad_angle": "  '{text}' 不是角度:角度是十进制数字,单位度(如 45、-30.5)",
        "limit": "  {name} 的范围是 {lower:.1f}° 到 {upper:.1f}°,{angle} 超出范围,未发送",
        "batch_form": "  batch 命令格式:batch a0 a1 a2 a3 a4(可加第 6 个值作为夹爪角度)",
        "grip_form": "  grip 命令格式:grip 角度(如 'grip 30',范围 {lower:.1f}° 到 {upper:.1f}°)",
        "name_form": "  {command} 命令格式:{command} 名字(一个词,不含空格,最多 {max} 个字符,如 '{command} a')",
        "no_args": "  '{command}' 不带参数,收到 '{text}'",
        "snapshot_form": "  snapshot 命令格式:snapshot [文件](默认 out/snapshot.png)",
        "snapshot": "  → 快照已写入 {path}",
        "snapshot_failed": "  快照失败: {error}",
        "no_state_snapshot": "  还没有收到 joint_state(仿真节点在运行吗?),无法拍快照",
        "xyz_form": "  xyz 命令格式:xyz X Y Z(末端目标点,单位毫米,基座坐标系:x 向前,y 向左,z 向上;如 'xyz 200 0 150')",
        "bad_mm": "  '{text}' 不是坐标:坐标是十进制数字,单位毫米(如 200、-35.5)",
        "sent_tip": "  → 末端 → ({x:g}, {y:g}, {z:g}) mm:关节 {angles}°",
        "landed": "  末端停在 ({x:.1f}, {y:.1f}, {z:.1f}) mm,离目标 ({tx:g}, {ty:g}, {tz:g}) {off:.1f} mm:舵机没有把关节完全转到目标角度",
        "unreachable": "  够不到 ({x:g}, {y:g}, {z:g}) mm:最近能到的点是 ({nx:.0f}, {ny:.0f}, {nz:.0f}) mm(差 {error:.0f} mm),未发送",
        "below_floor": "  ({x:g}, {y:g}, {z:g}) mm 在地面以下(z < 0,基座底面是 z = 0),未发送",
        "through_floor": "  到 ({x:g}, {y:g}, {z:g}) mm 的直接移动会碰到地面,未发送(分几步走,或先 home)",
        "where": "  末端位置: ({x:.1f}, {y:.1f}, {z:.1f}) mm(基座坐标系)",
        "no_state_where": "  还没有收到 joint_state(仿真节点在运行吗?),不知道末端在哪里",
        "no_kinematics": "  无法计算运动学: {error}",
        "jog_needs_terminal": "  jog 需要终端(键盘),标准输入不是终端",
        "jog_no_state": "  还没有收到 joint_state(仿真节点在运行吗?),无法点动",
        "jog_left": "  已退出点动模式",
        "record_form": "  record 命令格式:record 任务描述(如 'record 把方块放进盒子')",
        "record_off": "  录制未开启:用 so101 teleop --record 文件夹 启动",
        "recorder_silent": "  录制节点 {seconds:g} 秒内没有回答",
        "body_silent": "  {seconds:.0f} 秒没有收到 joint_state:仿真(或机械臂驱动)、它所在的机器或网络已断开,命令未发送",
        "reset_form": "  reset 命令格式:reset [种子](种子是 ≥ 0 的整数,如 'reset 7';不写则用下一个种子)",
        "task_off": "  没有任务:用 so101 teleop --task cube_to_box 启动",
        "policy_form": "  policy 命令格式:policy on(策略开始驾驶)或 policy off(停下)",
        "policy_none": "  没有策略:用 so101 teleop --task cube_to_box --policy 文件夹 启动",
        "policy_asked": "  → 已告诉策略:{word}",
        "expert_started": "  → 专家开始做任务;键入任何动作命令即接管",
        "task_silent": "  仿真节点 {seconds:g} 秒内没有回答",
        "laid_out": "  → 按种子 {seed} 重新摆放,机械臂回零位:{layout}",
        "layout": "方块在 ({x:.0f}, {y:.0f}) mm,偏航 {yaw:.0f}°;盒子在 ({box_x:.0f}, {box_y:.0f}) mm",
        "task_line": "  任务 {task},种子 {seed}:{layout}",
        "cube_now": "  方块现在在 ({x:.0f}, {y:.0f}, {z:.0f}) mm:{verdict}",
        "in_box": "在盒中",
        "not_in_box": "不在盒中",
        "landed_in_box": "  ★ 方块进了盒子(任务 {task},种子 {seed})",
        "left_box": "  方块已离开它在盒中停放的位置(任务 {task},种子 {seed})",
        "no_task_state": "  还没有收到 object_state(仿真节点在运行吗?)",
        "help": [
            "  命令格式:",
            "    关节号 角度              如 '0 45'(关节号 0-4 手臂,5 夹爪)",
            "    batch a0 a1 a2 a3 a4 [夹爪]  5 个关节同时设目标,如 'batch 0 -30 45 -20 10'",
            "    grip 角度 / open / close  夹爪角度 / 张开 ({open:g}°) / 闭合 ({closed:g}°)",
            "    home                    回零(手臂 5 个关节)",
            "    list                    显示关节列表",
            "    state                   显示当前关节角度(来自 joint_state)",
            "    save 名字               保存当前姿态(来自 joint_state)",
            "    go 名字                 移动到已保存的姿态",
            "    poses                   显示已保存的姿态",
            "    snapshot [文件]          把当前姿态画成 PNG(无需窗口,默认 out/snapshot.png)",
            "    xyz X Y Z               末端移到该点(毫米,基座坐标系:x 向前,y 向左,z 向上)",
            "    where                   显示末端当前位置(毫米)",
            "    jog                     键盘点动(W/S 抬起/放下,A/D 左/右转,E 开始/结束录制,Esc 返回)",
            "    record 任务描述          开始录制一段(需 so101 teleop --record 文件夹)",
            "    stop / discard          结束并保存这一段 / 放弃这一段",
            "    episodes                显示已保存的片段",
            "    reset [种子]             重新摆放任务场景(默认下一个种子),机械臂回零位(需 so101 teleop --task)",
            "    task                    显示任务、摆放和方块是否在盒中",
            "    expert                  脚本专家把任务做一遍(需 so101 teleop --task;键入任何动作命令即接管)",
            "    policy on / policy off  训练好的策略开始驾驶 / 停下(需 so101 teleop --policy 文件夹;键入任何动作命令即接管)",
            "    help                    显示本帮助",
            "    quit / exit             退出(也可 Ctrl-D、Ctrl-C)",
            "  超出关节限位的角度不会发送(会提示范围)。",
        ],
    },
    "en": {
        "title": "  SO-101 keyboard control",
        "poses_file": "  poses file: {path} ({count} saved)",
        "stopped": "  the dataflow stopped: quitting",
        "joint_line": "    {index}: {name} ({label})",
        "sent_joint": "  → joint {index} ({name}) → {angle}°",
        "sent_batch": "  → all joints → {angles}°",
        "sent_batch_gripper": "  → all joints → {angles}°, gripper → {gripper}°",
        "sent_home": "  → home command sent",
        "saved": "  → pose '{name}' saved: {angles}°",
        "saved_gripper": "  → pose '{name}' saved: {angles}°, gripper {gripper}°",
        "saved_not_persisted": "  → pose '{name}' saved for this run only (writing the file failed: {error})",
        "no_state": "  no joint_state received yet (is the simulation running?): cannot save a pose",
        "state": "  joint angles now: {angles}°",
        "state_gripper": "  joint angles now: {angles}°, gripper {gripper}°",
        "no_state_yet": "  no joint_state received yet (is the simulation running?)",
        "go": "  → moving to pose '{name}'",
        "unknown_pose": "  no pose '{name}'; saved poses: {known} (save one with 'save NAME')",
        "no_poses": "  no saved poses yet (save the current pose with 'save NAME')",
        "pose_line": "    {name}: {angles}°",
        "pose_line_gripper": "    {name}: {angles}°, gripper {gripper}°",
        "none": "none",
        "bye": "  bye",
        "unknown": "  cannot read '{text}': use 'JOINT ANGLE' (e.g. '0 45'), batch, grip, open, close, home, list, "
        "state, save, go, poses, snapshot, xyz, where, jog, record, stop, discard, episodes, reset, task, expert, policy, help, quit (type help)",
        "joint_form": "  format: JOINT ANGLE (e.g. '0 45'), JOINT 0-5 (5 = gripper)",
        "joint_range": "  joints are 0-5 (0-4 arm, 5 gripper), got '{text}'; format: JOINT ANGLE (e.g. '0 45')",
        "bad_angle": "  '{text}' is not an angle: angles are decimal numbers in degrees (e.g. 45, -30.5)",
        "limit": "  {name} accepts {lower:.1f}° to {upper:.1f}°; {angle} is out of range: not sent",
        "batch_form": "  batch format: batch a0 a1 a2 a3 a4 (a sixth value sets the gripper)",
        "grip_form": "  grip format: grip ANGLE (e.g. 'grip 30', {lower:.1f}° to {upper:.1f}°)",
        "name_form": "  {command} format: {command} NAME (one word, no spaces, at most {max} characters, e.g. '{command} a')",
        "no_args": "  '{command}' takes no arguments, got '{text}'",
        "snapshot_form": "  snapshot format: snapshot [FILE] (default out/snapshot.png)",
        "snapshot": "  → snapshot written to {path}",
        "snapshot_failed": "  snapshot failed: {error}",
        "no_state_snapshot": "  no joint_state received yet (is the simulation running?): no snapshot",
        "xyz_form": "  xyz format: xyz X Y Z (the tip's target in millimetres, base frame: x forward, y left, z up; "
        "e.g. 'xyz 200 0 150')",
        "bad_mm": "  '{text}' is not a coordinate: coordinates are decimal numbers in millimetres (e.g. 200, -35.5)",
        "sent_tip": "  → tip → ({x:g}, {y:g}, {z:g}) mm: joints {angles}°",
        "landed": "  the tip settled at ({x:.1f}, {y:.1f}, {z:.1f}) mm, {off:.1f} mm from ({tx:g}, {ty:g}, {tz:g}): "
        "the servos hold the joints a little off their goals",
        "unreachable": "  ({x:g}, {y:g}, {z:g}) mm is out of reach: the nearest point reached is ({nx:.0f}, {ny:.0f}, {nz:.0f}) mm "
        "({error:.0f} mm away); not sent",
        "below_floor": "  ({x:g}, {y:g}, {z:g}) mm is below the floor (z < 0; the base stands at z = 0): not sent",
        "through_floor": "  the straight move to ({x:g}, {y:g}, {z:g}) mm would hit the floor: not sent (go in steps, or home first)",
        "where": "  tip at ({x:.1f}, {y:.1f}, {z:.1f}) mm (base frame)",
        "no_state_where": "  no joint_state received yet (is the simulation running?): the tip's place is unknown",
        "no_kinematics": "  cannot compute the kinematics: {error}",
        "jog_needs_terminal": "  jog needs a terminal (a keyboard): stdin is not one",
        "jog_no_state": "  no joint_state received yet (is the simulation running?): cannot jog",
        "jog_left": "  left jog mode",
        "record_form": "  record format: record TASK TEXT (e.g. 'record put the cube in the box')",
        "record_off": "  recording is off: start with so101 teleop --record DIR",
        "recorder_silent": "  the recorder did not answer within {seconds:g} s",
        "body_silent": "  no joint_state for {seconds:.0f} s: the simulation (or the arm's driver), its machine or the network "
        "is gone; not sent",
        "reset_form": "  reset format: reset [SEED] (a whole number >= 0, e.g. 'reset 7'; without one, the next seed)",
        "task_off": "  no task: start with so101 teleop --task cube_to_box",
        "policy_form": "  policy format: policy on (it drives) or policy off (it stops)",
        "policy_none": "  no policy: start with so101 teleop --task cube_to_box --policy DIR",
        "policy_asked": "  → told the policy: {word}",
        "expert_started": "  → the expert is doing the task; any move you type takes over",
        "task_silent": "  the simulation did not answer within {seconds:g} s",
        "laid_out": "  → laid out from seed {seed}, the arm at home: {layout}",
        "layout": "cube at ({x:.0f}, {y:.0f}) mm, yaw {yaw:.0f}°; box at ({box_x:.0f}, {box_y:.0f}) mm",
        "task_line": "  task {task}, seed {seed}: {layout}",
        "cube_now": "  the cube is now at ({x:.0f}, {y:.0f}, {z:.0f}) mm: {verdict}",
        "in_box": "in the box",
        "not_in_box": "not in the box",
        "landed_in_box": "  ★ the cube is in the box (task {task}, seed {seed})",
        "left_box": "  the cube is no longer where it lay in the box (task {task}, seed {seed})",
        "no_task_state": "  no object_state received yet (is the simulation running?)",
        "help": [
            "  commands:",
            "    JOINT ANGLE             e.g. '0 45' (JOINT 0-4 arm, 5 gripper)",
            "    batch a0 a1 a2 a3 a4 [gripper]  all five joints at once, e.g. 'batch 0 -30 45 -20 10'",
            "    grip ANGLE / open / close  gripper angle / open ({open:g}°) / close ({closed:g}°)",
            "    home                    all five arm joints to 0°",
            "    list                    list the joints",
            "    state                   show the joint angles now (from joint_state)",
            "    save NAME               save the current pose (from joint_state)",
            "    go NAME                 move to a saved pose",
            "    poses                   list the saved poses",
            "    snapshot [FILE]         draw the arm as it is now to a PNG (no window needed; default out/snapshot.png)",
            "    xyz X Y Z               move the gripper tip there (millimetres, base frame: x forward, y left, z up)",
            "    where                   where the gripper tip is now (millimetres)",
            "    jog                     jog with keys (W/S raise/lower, A/D turn, E starts/stops an episode, Esc back)",
            "    record TASK TEXT        start recording an episode (with so101 teleop --record DIR)",
            "    stop / discard          end the episode and save it / drop it",
            "    episodes                list the saved episodes",
            "    reset [SEED]            lay the task's scene out again (default: the next seed), the arm home (with so101 teleop --task)",
            "    task                    the task, its layout, and whether the cube is in the box",
            "    expert                  the scripted expert does the task once (with so101 teleop --task; any move you type takes over)",
            "    policy on / policy off  a trained policy drives / stops (with so101 teleop --policy DIR; any move you type takes over)",
            "    help                    this help",
            "    quit / exit             quit (Ctrl-D and Ctrl-C quit too)",
            "  Angles beyond a joint's limits are not sent (the reply gives the range).",
        ],
    },
}


def texts(lang: str) -> dict:
    return TEXT["en" if lang == "en" else "zh"]


def format_angle(angle_deg: float) -> str:
    """90.0 -> '90', -30.5 -> '-30.5': the course prints '0 90' as '→ 90°'."""
    return f"{angle_deg:g}"


def format_angles(angles_deg) -> str:
    """The course's list form, '[-30.0, 45.0, -60.0, 30.0, 0.0]', rounded to 0.01° (+ 0.0: no '-0.0')."""
    return str([round(float(angle), 2) + 0.0 for angle in angles_deg])


def help_lines(lang: str) -> list[str]:
    return [line.format(open=GRIPPER_OPEN_DEG, closed=GRIPPER_CLOSED_DEG) for line in texts(lang)["help"]]


def joint_lines(lang: str) -> list[str]:
    text = texts(lang)
    return [
        text["joint_line"].format(index=index, name=joint.name, label=joint.label_zh if lang != "en" else joint.label_en)
        for index, joint in enumerate(ACTUATED_JOINTS)
    ]


def _angle(word: str, joint_position: int, text: dict) -> float | ParseError:
    if not _NUMBER.match(word):
        return ParseError(text["bad_angle"].format(text=word))
    angle = float(word)
    if not math.isfinite(angle):  # "1e999"
        return ParseError(text["bad_angle"].format(text=word))
    joint = ACTUATED_JOINTS[joint_position]
    # The limits are shown to 0.1° (110.0° for 1.91986 rad = 109.9999°), so the shown values must be accepted;
    # the hair beyond the exact URDF limit is then clamped away.
    if not joint.allows_deg(angle, decimals=1):
        return ParseError(
            text["limit"].format(name=joint.name, lower=joint.lower_deg, upper=joint.upper_deg, angle=word)
        )
    return joint.clamp_deg(angle)


def _set_joint(index: int, word: str, text: dict) -> SetJoint | ParseError:
    angle = _angle(word, index, text)
    return angle if isinstance(angle, ParseError) else SetJoint(index, angle)


def _pose_name(command: str, words: list[str], text: dict) -> str | ParseError:
    if len(words) != 2 or len(words[1]) > MAX_POSE_NAME_CHARS:
        return ParseError(text["name_form"].format(command=command, max=MAX_POSE_NAME_CHARS))
    return words[1]


NO_ARGUMENT_COMMANDS: dict[str, Command] = {
    "home": Home(), "list": ListJoints(), "state": ShowState(), "poses": ListPoses(), "help": Help(), "?": Help(),
    "quit": Quit(), "exit": Quit(), "where": Where(), "jog": JogKeys(),
    "stop": Episodes("stop"), "discard": Episodes("discard"), "episodes": Episodes("episodes"), "task": ShowTask(),
    "expert": RunExpert(), "open": SetJoint(GRIPPER_COMMAND_INDEX, GRIPPER_OPEN_DEG),
    "close": SetJoint(GRIPPER_COMMAND_INDEX, GRIPPER_CLOSED_DEG),
}


def parse_command(line: str, lang: str = "zh") -> Command | ParseError:
    """One typed line -> the command it names, or a ParseError whose message gives the valid form."""
    text = texts(lang)
    # Pose names keep their case; command words do not ("HOME" works).
    words = [word for word in _SEPARATORS.split(line.strip()) if word]
    if not words:
        return Empty()
    keyword = words[0].lower()
    shown = " ".join(words)

    if keyword in NO_ARGUMENT_COMMANDS:
        if len(words) > 1:
            return ParseError(text["no_args"].format(command=keyword, text=shown))
        return NO_ARGUMENT_COMMANDS[keyword]

    if keyword == "record":
        # The task is the rest of the line as typed (commas and spacing are part of a sentence).
        task = " ".join(line.strip()[len(words[0]):].split())
        return Episodes("record", task) if task else ParseError(text["record_form"])

    if keyword == "policy":
        if len(words) != 2 or words[1].lower() not in ("on", "off"):
            return ParseError(text["policy_form"])
        return RunPolicy(words[1].lower())

    if keyword == "reset":
        if len(words) == 1:
            return ResetTask()
        if len(words) != 2 or not words[1].isdecimal():  # full-width digits too, as for joints
            return ParseError(text["reset_form"])
        return ResetTask(int(words[1]))

    if keyword == "batch":
        values = words[1:]
        if len(values) not in (NUM_ARM_JOINTS, NUM_ARM_JOINTS + 1):
            return ParseError(text["batch_form"])
        angles = []
        for position, word in enumerate(values):
            angle = _angle(word, position, text)
            if isinstance(angle, ParseError):
                return angle
            angles.append(angle)
        return Batch(tuple(angles))

    if keyword == "grip":
        if len(words) != 2:
            return ParseError(text["grip_form"].format(lower=GRIPPER.lower_deg, upper=GRIPPER.upper_deg))
        return _set_joint(GRIPPER_COMMAND_INDEX, words[1], text)

    if keyword in ("save", "go"):
        name = _pose_name(keyword, words, text)
        if isinstance(name, ParseError):
            return name
        return SavePose(name) if keyword == "save" else GoPose(name)

    if keyword == "xyz":
        if len(words) != 4:
            return ParseError(text["xyz_form"])
        for word in words[1:]:
            if not _NUMBER.match(word) or not math.isfinite(float(word)):
                return ParseError(text["bad_mm"].format(text=word))
        x, y, z = (float(word) for word in words[1:])
        return MoveTip((x, y, z))

    if keyword == "snapshot":
        if len(words) > 2:
            return ParseError(text["snapshot_form"])
        return Snapshot(*words[1:])

    if _NUMBER.match(keyword):
        if len(words) != 2:
            return ParseError(text["joint_form"])
        if not keyword.lstrip("+").isdigit() or int(keyword) >= len(ACTUATED_JOINTS):
            return ParseError(text["joint_range"].format(text=words[0]))
        return _set_joint(int(keyword), words[1], text)

    return ParseError(text["unknown"].format(text=shown if len(shown) <= 40 else shown[:37] + "..."))

