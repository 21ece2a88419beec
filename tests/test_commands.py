"""The prompt's parser: typed text -> a command, or a one-line error that gives the valid form."""

from __future__ import annotations

import pytest

from so101.prompt.commands import (
    GRIPPER_CLOSED_DEG, GRIPPER_OPEN_DEG, Batch, Empty, GoPose, Help, Home, ListJoints, ListPoses, ParseError,
    Quit, ResetTask, SavePose, SetJoint, ShowState, ShowTask, Snapshot, format_angle, format_angles, help_lines, joint_lines, parse_command,
)


@pytest.mark.parametrize(
    "line, command",
    [
        ("0 90", SetJoint(0, 90.0)),
        ("1 -45", SetJoint(1, -45.0)),
        ("  4   12.5  ", SetJoint(4, 12.5)),
        ("3 +.5", SetJoint(3, 0.5)),
        ("5 30", SetJoint(5, 30.0)),
        ("0,90", SetJoint(0, 90.0)),
        ("０ ９０", SetJoint(0, 90.0)),  # full-width digits, as a Chinese input method types them
        ("batch -30 45 -60 30 0", Batch((-30.0, 45.0, -60.0, 30.0, 0.0))),
        ("batch -30,45,-60,30,0", Batch((-30.0, 45.0, -60.0, 30.0, 0.0))),
        ("batch 0 -30 45 -20 10 50", Batch((0.0, -30.0, 45.0, -20.0, 10.0, 50.0))),
        ("grip 30", SetJoint(5, 30.0)),
        ("open", SetJoint(5, GRIPPER_OPEN_DEG)),
        ("close", SetJoint(5, GRIPPER_CLOSED_DEG)),
        ("home", Home()),
        ("HOME", Home()),
        ("snapshot", Snapshot("out/snapshot.png")),
        ("snapshot arm.png", Snapshot("arm.png")),
        ("list", ListJoints()),
        ("state", ShowState()),
        ("save a", SavePose("a")),
        ("save 抓取位", SavePose("抓取位")),
        ("go Pick", GoPose("Pick")),
        ("poses", ListPoses()),
        ("help", Help()),
        ("quit", Quit()),
        ("exit", Quit()),
        ("reset", ResetTask()),
        ("reset 7", ResetTask(7)),
        ("RESET 0", ResetTask(0)),
        ("reset ７", ResetTask(7)),
        ("task", ShowTask()),
        ("", Empty()),
        ("   ", Empty()),
    ],
)
def test_valid_lines(line, command):
    assert parse_command(line) == command


@pytest.mark.parametrize(
    "line, expected_zh, expected_en",
    [
        ("abc", "无法识别 'abc'", "cannot read 'abc'"),
        ("0", "格式错误:关节号 角度(如 '0 45')", "format: JOINT ANGLE (e.g. '0 45')"),
        ("0 90 1", "格式错误:关节号 角度", "format: JOINT ANGLE"),
        ("0 abc", "'abc' 不是角度", "'abc' is not an angle"),
        ("0 nan", "'nan' 不是角度", "'nan' is not an angle"),
        ("0 inf", "'inf' 不是角度", "'inf' is not an angle"),
        ("0 -inf", "'-inf' 不是角度", "'-inf' is not an angle"),
        ("0 1e999", "'1e999' 不是角度", "'1e999' is not an angle"),
        ("0 1_0", "'1_0' 不是角度", "'1_0' is not an angle"),
        ("9 10", "关节号范围 0-5", "joints are 0-5"),
        ("-1 10", "关节号范围 0-5", "joints are 0-5"),
        ("1.5 10", "关节号范围 0-5", "joints are 0-5"),
        ("0 200", "shoulder_pan 的范围是 -110.0° 到 110.0°,200 超出范围,未发送",
         "shoulder_pan accepts -110.0° to 110.0°; 200 is out of range: not sent"),
        ("4 -160", "wrist_roll 的范围是 -157.2° 到 162.8°", "wrist_roll accepts -157.2° to 162.8°"),
        ("5 120", "gripper 的范围是 -10.0° 到 100.0°", "gripper accepts -10.0° to 100.0°"),
        ("batch", "batch 命令格式:batch a0 a1 a2 a3 a4", "batch format: batch a0 a1 a2 a3 a4"),
        ("batch 1 2 3 4", "batch 命令格式", "batch format"),
        ("batch 1 2 3 4 5 6 7", "batch 命令格式", "batch format"),
        ("batch 0 0 nan 0 0", "'nan' 不是角度", "'nan' is not an angle"),
        ("batch 0 120 0 0 0", "shoulder_lift 的范围是 -100.0° 到 100.0°", "shoulder_lift accepts -100.0° to 100.0°"),
        ("grip", "grip 命令格式:grip 角度", "grip format: grip ANGLE"),
        ("grip x", "'x' 不是角度", "'x' is not an angle"),
        ("save", "save 命令格式:save 名字", "save format: save NAME"),
        ("save a b", "save 命令格式", "save format"),
        ("go", "go 命令格式:go 名字", "go format: go NAME"),
        ("save " + "x" * 41, "最多 40 个字符", "at most 40 characters"),
        ("home now", "'home' 不带参数", "'home' takes no arguments"),
        ("snapshot a.png b.png", "snapshot 命令格式:snapshot [文件]", "snapshot format: snapshot [FILE]"),
        ("reset x", "reset 命令格式:reset [种子]", "reset format: reset [SEED]"),
        ("reset -1", "reset 命令格式", "reset format"),
        ("reset 1.5", "reset 命令格式", "reset format"),
        ("reset 1 2", "reset 命令格式", "reset format"),
        ("task 3", "'task' 不带参数", "'task' takes no arguments"),
    ],
)
def test_invalid_lines_get_one_line_saying_the_valid_form(line, expected_zh, expected_en):
    for lang, expected in (("zh", expected_zh), ("en", expected_en)):
        result = parse_command(line, lang)
        assert isinstance(result, ParseError), (line, result)
        assert expected in result.message
        assert "\n" not in result.message


def test_the_limits_as_shown_are_accepted_and_clamped_to_the_exact_urdf_limit():
    # shoulder_pan's URDF limit is 1.91986 rad = 109.9999°, shown as 110.0°
    at_limit = parse_command("0 110")
    assert at_limit.index == 0 and at_limit.angle_deg == pytest.approx(109.9999, abs=1e-4)
    assert at_limit.angle_deg <= 110.0
    assert format_angle(at_limit.angle_deg) == "110"
    assert isinstance(parse_command("0 110.1"), ParseError)
    assert parse_command("5 -10").angle_deg == pytest.approx(-10.0, abs=1e-3)


def test_replies_are_formatted_as_the_course_shows_them():
    assert format_angle(90.0) == "90"
    assert format_angle(-30.5) == "-30.5"
    assert format_angles([-30, 45, -60, 30, 0]) == "[-30.0, 45.0, -60.0, 30.0, 0.0]"
    assert format_angles([12.3456]) == "[12.35]"
    assert format_angles([-0.001]) == "[0.0]"


def test_list_shows_the_course_joint_names_and_the_gripper():
    assert joint_lines("zh") == [
        "    0: shoulder_pan (基座旋转)",
        "    1: shoulder_lift (大臂抬起)",
        "    2: elbow_flex (肘部弯曲)",
        "    3: wrist_flex (手腕俯仰)",
        "    4: wrist_roll (手腕旋转)",
        "    5: gripper (夹爪)",
    ]
    assert joint_lines("en")[0] == "    0: shoulder_pan (base rotation)"


@pytest.mark.parametrize("lang", ["zh", "en"])
def test_help_names_every_command(lang):
    text = "\n".join(help_lines(lang))
    for word in ("batch", "grip", "open", "close", "home", "list", "state", "save", "go", "poses", "reset", "task", "help",
                 "quit"):
        assert word in text
    assert "100°" in text and "0°" in text
