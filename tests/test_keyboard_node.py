"""The keyboard node's command handling, without a daemon: the joint_cmd arrays it sends and its replies."""

from __future__ import annotations

import io
import json
import math
import re
import threading
import types

import pyarrow as pa
import pytest
from dora.testing import MockNode

from nodes import keyboard_control
from nodes.keyboard_control import EventPump, joint_cmd_sender, run_prompt
from so101.prompt.control import KeyboardControl
from so101.prompt.poses import PoseStore

STATE_DEG = [-30.004, 44.981, -59.687, 30.0, -0.001]
GRIPPER_DEG = 12.345


def sent(node) -> list[list[float]]:
    arrays = node.outputs.get("joint_cmd", [])
    assert all(array.type == pa.float64() for array in arrays)
    return [array.to_pylist() for array in arrays]


def make_control(tmp_path, lang="zh", events=()):
    """A KeyboardControl sending through a MockNode, fed `events` by the real EventPump."""
    node = MockNode(list(events))
    control = KeyboardControl(joint_cmd_sender(node), PoseStore(tmp_path / "poses.json"), lang)
    stops = []
    pump = EventPump(node, control, on_stop=lambda: stops.append(True))
    pump.run()  # in this thread: the MockNode's events end with STOP
    assert stops == [True]
    return node, control


def state_events():
    return [("joint_state", pa.array(STATE_DEG)), ("gripper_state", pa.array([GRIPPER_DEG]))]


def test_the_course_script_sends_these_arrays_and_replies_these_lines(tmp_path):
    node, control = make_control(tmp_path, events=state_events())
    replies = []
    for line in ["0 90", "1 -45", "batch -30 45 -60 30 0", "save a", "home", "go a", "grip 30", "open", "close"]:
        lines, quit_now = control.handle_line(line)
        assert not quit_now
        replies += lines
    assert replies == [
        "  → 关节 0 (shoulder_pan) → 90°",
        "  → 关节 1 (shoulder_lift) → -45°",
        "  → 全关节 → [-30.0, 45.0, -60.0, 30.0, 0.0]°",
        "  → 姿态 'a' 已保存: [-30.0, 44.98, -59.69, 30.0, 0.0]°,夹爪 12.35°",
        "  → 回零指令已发送",
        "  → 移动到姿态 'a'",
        "  → 关节 5 (gripper) → 30°",
        "  → 关节 5 (gripper) → 100°",
        "  → 关节 5 (gripper) → 0°",
    ]
    assert sent(node) == [
        [0.0, 90.0],
        [1.0, -45.0],
        [-30.0, 45.0, -60.0, 30.0, 0.0],
        [0.0, 0.0, 0.0, 0.0, 0.0],
        [-30.0, 44.98, -59.69, 30.0, 0.0, 12.35],
        [5.0, 30.0],
        [5.0, 100.0],
        [5.0, 0.0],
    ]
    assert json.loads((tmp_path / "poses.json").read_text()) == {
        "a": {"joints_deg": [-30.0, 44.98, -59.69, 30.0, 0.0], "gripper_deg": 12.35}
    }


def test_english_replies(tmp_path):
    node, control = make_control(tmp_path, lang="en", events=state_events())
    assert control.handle_line("0 90")[0] == ["  → joint 0 (shoulder_pan) → 90°"]
    assert control.handle_line("batch -30 45 -60 30 0 20")[0] == [
        "  → all joints → [-30.0, 45.0, -60.0, 30.0, 0.0]°, gripper → 20°"
    ]
    assert control.handle_line("home")[0] == ["  → home command sent"]
    assert control.handle_line("go b")[0] == ["  no pose 'b'; saved poses: none (save one with 'save NAME')"]
    assert sent(node) == [[0.0, 90.0], [-30.0, 45.0, -60.0, 30.0, 0.0, 20.0], [0.0] * 5]


@pytest.mark.parametrize("line", ["abc", "0", "0 abc", "0 nan", "0 inf", "9 10", "0 200", "batch 1 2", "go nowhere",
                                  "save", "list", "state", "help", "poses", ""])
def test_lines_that_move_nothing_send_nothing(tmp_path, line):
    node, control = make_control(tmp_path)
    replies, quit_now = control.handle_line(line)
    assert not quit_now
    assert sent(node) == []
    assert all("\n" not in reply for reply in replies)


def test_invalid_input_gets_one_reply_line_with_the_valid_form(tmp_path):
    _, control = make_control(tmp_path)
    assert control.handle_line("9 10")[0] == ["  关节号范围 0-5(0-4 手臂,5 夹爪),收到 '9';格式:关节号 角度(如 '0 45')"]
    assert control.handle_line("go zz")[0] == ["  未找到姿态 'zz';已保存的姿态: 无(用 'save 名字' 保存)"]


def test_state_shows_the_latest_angles(tmp_path):
    _, control = make_control(tmp_path, events=state_events())
    assert control.handle_line("state")[0] == ["  当前关节角度: [-30.0, 44.98, -59.69, 30.0, 0.0]°,夹爪 12.35°"]
    _, without = make_control(tmp_path / "other", lang="en")
    assert without.handle_line("state", state_wait_s=0)[0] == [
        "  no joint_state received yet (is the simulation running?)"
    ]


def test_save_without_any_joint_state_says_so_and_writes_nothing(tmp_path):
    node, control = make_control(tmp_path, lang="en")
    assert control.handle_line("save a", state_wait_s=0)[0] == [
        "  no joint_state received yet (is the simulation running?): cannot save a pose"
    ]
    assert not (tmp_path / "poses.json").exists()


def test_save_waits_for_the_first_joint_state(tmp_path):
    control = KeyboardControl(lambda angles_deg: None, PoseStore(tmp_path / "poses.json"), "en")
    arrival = threading.Timer(0.1, control.on_event, [{"type": "INPUT", "id": "joint_state", "value": pa.array([1.0] * 5)}])
    arrival.start()
    replies, _ = control.handle_line("save a", state_wait_s=30)
    arrival.join()
    assert replies == ["  → pose 'a' saved: [1.0, 1.0, 1.0, 1.0, 1.0]°"]


def test_the_latest_state_is_the_one_saved(tmp_path):
    events = [("joint_state", pa.array([float(i)] * 5)) for i in range(20)]
    _, control = make_control(tmp_path, lang="en", events=events)
    control.handle_line("save last")
    assert control.poses.get("last").joints_deg == (19.0,) * 5
    assert control.poses.get("last").gripper_deg is None


def test_saved_poses_are_there_after_a_restart(tmp_path):
    _, first = make_control(tmp_path, events=state_events())
    first.handle_line("save a")
    node, second = make_control(tmp_path)
    assert second.handle_line("poses")[0] == ["    a: [-30.0, 44.98, -59.69, 30.0, 0.0]°,夹爪 12.35°"]
    second.handle_line("go a")
    assert sent(node) == [[-30.0, 44.98, -59.69, 30.0, 0.0, 12.35]]


def test_quit_and_exit_quit(tmp_path):
    _, control = make_control(tmp_path)
    assert control.handle_line("quit") == (["  再见"], True)
    assert control.handle_line("exit") == (["  再见"], True)


def test_a_piped_script_runs_in_order_echoes_and_stops_at_quit(tmp_path, monkeypatch, capsys):
    node, control = make_control(tmp_path, lang="en", events=state_events())
    monkeypatch.setattr("sys.stdin", io.StringIO("0 90\nbogus\nsave a\nquit\n1 10\n"))
    run_prompt(control, interactive=False, history_file=tmp_path / "history")
    assert capsys.readouterr().out.splitlines() == [
        "> 0 90",
        "  → joint 0 (shoulder_pan) → 90°",
        "> bogus",
        "  cannot read 'bogus': use 'JOINT ANGLE' (e.g. '0 45'), batch, grip, open, close, home, list, state, save, "
        "go, poses, snapshot, xyz, where, jog, record, stop, discard, episodes, reset, task, expert, policy, help, quit (type help)",
        "> save a",
        "  → pose 'a' saved: [-30.0, 44.98, -59.69, 30.0, 0.0]°, gripper 12.35°",
        "> quit",
        "  bye",
    ]
    assert sent(node) == [[0.0, 90.0]]
    assert not (tmp_path / "history").exists()


class FakeNode:
    """What main() needs of dora.Node: it hands out `events`, then waits (None), and records outputs."""

    def __init__(self, events):
        self.events = list(events)
        self.outputs = []

    def next(self, timeout=None):
        return self.events.pop(0) if self.events else None

    def try_recv(self):
        return self.next()

    def node_config(self):
        return {"inputs": {"joint_state": "simulation/joint_state"}, "outputs": ["joint_cmd"]}

    def send_output(self, output_id, data, metadata=None):
        self.outputs.append((output_id, data))


@pytest.fixture(autouse=True)
def prompt_log_in_tmp(tmp_path, monkeypatch):
    """main() sets dora's log lines aside in a file: the test's, not the checkout's out/."""
    monkeypatch.setenv("SO101_PROMPT_LOG", str(tmp_path / "prompt.log"))


def test_main_joins_as_keyboard_control_and_runs_a_piped_file_to_its_end(tmp_path, monkeypatch, capsys):
    import dora

    created = []

    def fake_node(node_id):
        created.append(node_id)
        node = FakeNode([{"type": "INPUT", "id": "joint_state", "value": pa.array([5.0, 4.0, 3.0, 2.0, 1.0])}])
        created.append(node)
        return node

    monkeypatch.setattr(dora, "Node", fake_node)
    monkeypatch.setenv("SO101_LANG", "en")
    monkeypatch.setenv("SO101_POSES_FILE", str(tmp_path / "poses.json"))
    monkeypatch.setattr("sys.stdin", io.StringIO("save p\nhome\ngo p\n"))
    assert keyboard_control.main([]) == 0
    assert created[0] == "keyboard_control"
    outputs = created[1].outputs
    assert [output_id for output_id, _ in outputs] == ["joint_cmd", "joint_cmd"]
    assert [data.to_pylist() for _, data in outputs] == [[0.0] * 5, [5.0, 4.0, 3.0, 2.0, 1.0]]
    assert all(data.type == pa.float64() for _, data in outputs)
    out = capsys.readouterr().out
    assert "  → pose 'p' saved: [5.0, 4.0, 3.0, 2.0, 1.0]°" in out and "  → moving to pose 'p'" in out
    assert json.loads((tmp_path / "poses.json").read_text())["p"]["joints_deg"] == [5.0, 4.0, 3.0, 2.0, 1.0]


def test_main_reports_a_corrupt_poses_file_in_one_line(tmp_path, monkeypatch, capsys):
    import dora

    (tmp_path / "poses.json").write_text("{not json")
    monkeypatch.setattr(dora, "Node", lambda node_id: FakeNode([]))
    monkeypatch.setenv("SO101_POSES_FILE", str(tmp_path / "poses.json"))
    monkeypatch.setattr("sys.stdin", io.StringIO(""))
    assert keyboard_control.main([]) == 0
    notice = [line for line in capsys.readouterr().out.splitlines() if "poses file" in line]
    assert len(notice) == 1 and "moved aside to poses.json.corrupt-" in notice[0]


def test_main_refuses_an_unknown_language(monkeypatch, capsys):
    monkeypatch.setenv("SO101_LANG", "fr")
    assert keyboard_control.main([]) == 2
    assert "SO101_LANG='fr' is not one of: zh, en" in capsys.readouterr().err


def test_main_without_a_running_dataflow_says_how_to_start_it(monkeypatch, capsys):
    import dora

    def no_daemon(node_id):
        raise RuntimeError("Could not setup node from node id.\n\nCaused by:\n   Connection refused\n\nLocation:\n  lib.rs:1")

    monkeypatch.setattr(dora, "Node", no_daemon)
    monkeypatch.setenv("SO101_LANG", "en")
    assert keyboard_control.main([]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "start it first in another terminal: `dora run dataflow.yml`" in err and "Connection refused" in err
    assert "lib.rs" not in err


def test_snapshot_draws_the_arm_as_it_is_now(tmp_path, monkeypatch):
    from tests.helpers.images import arm_pixels, png_rgb

    monkeypatch.chdir(tmp_path)
    _, control = make_control(tmp_path, lang="en", events=state_events())
    lines, _ = control.handle_line("snapshot now.png")
    assert lines == ["  → snapshot written to now.png"]
    rgb = png_rgb((tmp_path / "now.png").read_bytes())
    assert arm_pixels(rgb).sum() > 0.02 * rgb.shape[0] * rgb.shape[1]


def test_snapshot_without_state_or_with_a_bad_file_says_so_in_one_line(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _, control = make_control(tmp_path, lang="en")
    assert control.handle_line("snapshot", state_wait_s=0.0)[0] == [
        "  no joint_state received yet (is the simulation running?): no snapshot"
    ]
    _, control = make_control(tmp_path, lang="en", events=state_events())
    (tmp_path / "taken").write_text("a file, not a folder")
    (lines,), _ = control.handle_line("snapshot taken/now.png")
    assert lines.startswith("  snapshot failed: ")
    assert not (tmp_path / "taken" / "now.png").exists()


def test_main_says_so_in_one_line_when_the_log_file_cannot_be_written(tmp_path, monkeypatch, capsys):
    import dora

    (tmp_path / "a-file").write_text("")
    monkeypatch.setenv("SO101_PROMPT_LOG", str(tmp_path / "a-file" / "prompt.log"))
    monkeypatch.setattr(dora, "Node", lambda node_id: FakeNode([]))
    monkeypatch.setattr("sys.stdin", io.StringIO("quit\n"))
    assert keyboard_control.main([]) == 0
    out = capsys.readouterr().out
    assert f"  (dora's log lines are dropped: cannot write {tmp_path / 'a-file' / 'prompt.log'}: File exists)" in out
    assert "> quit" in out


# -- Cartesian targets: xyz and where ----------------------------------------------------------


@pytest.fixture(scope="module")
def kinematics():
    from so101.kinematics import Kinematics

    with Kinematics() as model:
        yield model


def test_xyz_sends_the_five_joints_that_put_the_tip_there(tmp_path, kinematics):
    node, control = make_control(tmp_path, "en", events=state_events())
    lines, _ = control.handle_line("xyz 200 0 150")
    assert lines[0].startswith("  → tip → (200, 0, 150) mm: joints [")
    (joints_deg,) = sent(node)
    assert len(joints_deg) == 5  # the arm only: the gripper stays as it is
    assert kinematics.tip_mm(joints_deg) == pytest.approx((200, 0, 150), abs=1.0)


def test_where_is_forward_kinematics_of_the_latest_state(tmp_path, kinematics):
    _, control = make_control(tmp_path, "en", events=state_events())
    x, y, z = kinematics.tip_mm(STATE_DEG)
    assert control.handle_line("where") == ([f"  tip at ({x:.1f}, {y:.1f}, {z:.1f}) mm (base frame)"], False)
    _, no_state = make_control(tmp_path, "en")
    assert no_state.handle_line("where", state_wait_s=0.01)[0] == [
        "  no joint_state received yet (is the simulation running?): the tip's place is unknown"]


@pytest.mark.parametrize("line, reply", [
    ("xyz 1000 0 0", r"  \(1000, 0, 0\) mm is out of reach: the nearest point reached is \(\d+, -?\d+, -?\d+\) mm "
                     r"\(\d+ mm away\); not sent"),
    ("xyz 200 0 -5", r"  \(200, 0, -5\) mm is below the floor \(z < 0; the base stands at z = 0\): not sent"),
    ("xyz 200 0", r"  xyz format: xyz X Y Z \(the tip's target in millimetres, base frame: x forward, y left, z up; "
                  r"e\.g\. 'xyz 200 0 150'\)"),
    ("xyz 200 zero 150", r"  'zero' is not a coordinate: coordinates are decimal numbers in millimetres \(e\.g\. 200, -35\.5\)"),
    ("xyz inf 0 0", r"  'inf' is not a coordinate: .*"),
])
def test_xyz_that_cannot_be_done_sends_nothing_and_says_why_in_one_line(tmp_path, kinematics, line, reply):
    import re

    node, control = make_control(tmp_path, "en", events=state_events())
    lines, quit_now = control.handle_line(line)
    assert len(lines) == 1 and re.fullmatch(reply, lines[0]), lines
    assert not quit_now and sent(node) == []


def test_jog_without_a_terminal_says_so(tmp_path):
    node, control = make_control(tmp_path, "en", events=state_events())
    assert control.handle_line("jog") == (["  jog needs a terminal (a keyboard): stdin is not one"], False)
    assert sent(node) == []


def test_the_prompt_does_not_load_pybullet_until_asked():
    import subprocess
    import sys

    probe = ("import sys, nodes.keyboard_control; "
             "print(sorted(m for m in ('pybullet', 'numpy', 'so101.kinematics', 'so101.prompt.jog') if m in sys.modules))")
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=keyboard_control.ROOT)
    assert result.stdout.strip() == "[]", result.stderr


@pytest.mark.parametrize("port", ["0", "70000", "abc", "-5"])
def test_a_bad_daemon_port_is_one_line_and_exit_2(monkeypatch, capsys, port):
    monkeypatch.setenv("SO101_DAEMON_PORT", port)
    assert keyboard_control.main([]) == 2
    assert capsys.readouterr().err == f"keyboard_control: SO101_DAEMON_PORT={port!r} is not a port number (1-65535)\n"


def test_when_joint_state_stops_coming_commands_are_not_sent_and_one_line_says_why(tmp_path):
    import time

    node, control = make_control(tmp_path, "en", events=state_events())
    control.stopped = False  # the MockNode's STOP ended the pump; the dataflow "runs" on, silently
    assert control.handle_line("0 10")[0] == ["  → joint 0 (shoulder_pan) → 10°"]  # states just came
    control._last_state_at = time.monotonic() - 7.2
    for line in ("0 20", "state", "xyz 200 0 150", "save b"):
        assert control.handle_line(line) == ([
            "  no joint_state for 7 s: the simulation (or the arm's driver), its machine or the network is gone; not sent"],
            False)
    assert control.handle_line("help")[0][0] == "  commands:"  # what needs no arm still works
    assert sent(node) == [[0.0, 10.0]]


# -- after xyz: where the tip landed, once the arm stopped ------------------------------------


@pytest.mark.parametrize("lang, landed_line", [
    ("en", r"  the tip settled at \({x}, {y}, {z}\) mm, {off} mm from \(200, 0, 150\): "
           r"the servos hold the joints a little off their goals"),
    ("zh", r"  末端停在 \({x}, {y}, {z}\) mm,离目标 \(200, 0, 150\) {off} mm:舵机没有把关节完全转到目标角度"),
])
def test_xyz_says_where_the_tip_landed_when_the_servos_stop_it_off_target(tmp_path, kinematics, monkeypatch, lang, landed_line):
    clock = [100.0]
    monkeypatch.setattr("so101.prompt.control.time", types.SimpleNamespace(monotonic=lambda: clock[0]))
    node, control = make_control(tmp_path, lang, events=state_events())
    news = []
    control.show_news = news.append
    control.handle_line("xyz 200 0 150")
    (goal_deg,) = sent(node)
    sagged_deg = [goal_deg[0], goal_deg[1] + 1.5, goal_deg[2] + 1.0, *goal_deg[3:]]  # shoulder and elbow give

    def state(angles_deg, after_s):
        clock[0] += after_s
        control.on_event({"type": "INPUT", "id": "joint_state", "value": pa.array(angles_deg)})

    for step in range(20):  # on its way: still moving, nothing said
        state([angle * step / 20 + start * (1 - step / 20) for angle, start in zip(sagged_deg, STATE_DEG)], 0.02)
    assert news == []
    for _ in range(30):  # stopped off the goal: said once, after half a second still
        state(sagged_deg, 0.02)
    x, y, z = kinematics.tip_mm(sagged_deg)
    off = math.dist((x, y, z), (200, 0, 150))
    assert off > 2.0
    assert len(news) == 1
    assert re.fullmatch(landed_line.format(x=f"{x:.1f}", y=f"{y:.1f}", z=f"{z:.1f}", off=f"{off:.1f}"), news[0]), news


def test_xyz_says_nothing_when_the_tip_lands_on_target_or_another_command_came(tmp_path, kinematics, monkeypatch):
    clock = [100.0]
    monkeypatch.setattr("so101.prompt.control.time", types.SimpleNamespace(monotonic=lambda: clock[0]))
    node, control = make_control(tmp_path, "en", events=state_events())
    news = []
    control.show_news = news.append

    def settle_at(angles_deg):
        for _ in range(40):
            clock[0] += 0.02
            control.on_event({"type": "INPUT", "id": "joint_state", "value": pa.array(angles_deg)})

    control.handle_line("xyz 200 0 150")
    settle_at(sent(node)[-1])  # exactly on the goal: within 2 mm, not worth a line
    control.handle_line("xyz 200 0 150")
    control.handle_line("0 10")  # the next move is this one: the xyz's landing is not reported
    settle_at([angle + 3.0 for angle in sent(node)[-2]])
    assert news == []


def test_a_settle_watch_gives_up_on_an_arm_that_keeps_moving():
    from so101.prompt.landing import SETTLE_TIMEOUT_S, SettleWatch

    watch = SettleWatch(started_s=0.0)
    swinging = [watch.add(step * 0.02, [math.sin(step / 10.0)] * 5) for step in range(int(SETTLE_TIMEOUT_S / 0.02) + 10)]
    assert swinging == [None] * len(swinging) and watch.done
    assert watch.add(SETTLE_TIMEOUT_S + 1.0, [0.0] * 5) is None  # still, but too late


# -- a task (so101 teleop --task): `reset`, `task`, and the news of the cube ------------------------------

def task_control(tmp_path, lang="en", answer=True):
    """A KeyboardControl whose task link goes to a stand-in body: each `reset` is answered at once
    (unless `answer` is False), from seed 7 onward; returns (control, task_cmd texts sent, news lines)."""
    from so101.prompt.task_link import TaskLink

    node, control = make_control(tmp_path, lang, events=state_events())
    sent_cmds, news = [], []
    seed = [7]

    def send(task_cmd, request):
        sent_cmds.append(task_cmd)
        words = task_cmd.split()
        seed[0] = int(words[1]) if len(words) == 2 else seed[0] + 1
        if answer:
            control.task.on_status(False, {"task": "cube_to_box", "seed": seed[0], "reply_to": request})

    control.task = TaskLink(send, control.task_news)
    control.show_news = news.append
    return control, sent_cmds, news


def test_reset_lays_the_next_or_the_given_seed_out_and_says_where_the_cube_is(tmp_path):
    from so101.tasks import CUBE_TO_BOX

    control, sent_cmds, _ = task_control(tmp_path)
    assert control.handle_line("reset")[0] == [
        "  → laid out from seed 8, the arm at home: cube at ({x:.0f}, {y:.0f}) mm, yaw {yaw:.0f}°; box at (160, 190) mm".format(
            x=CUBE_TO_BOX.layout(8).cube_xyz_m[0] * 1000, y=CUBE_TO_BOX.layout(8).cube_xyz_m[1] * 1000,
            yaw=math.degrees(CUBE_TO_BOX.layout(8).cube_yaw_rad))]
    assert control.handle_line("reset 40")[0][0].startswith("  → laid out from seed 40, the arm at home: cube at (")
    assert sent_cmds == ["reset", "reset 40"]


def test_task_shows_the_layout_where_the_cube_is_and_whether_it_is_in_the_box(tmp_path):
    control, _, news = task_control(tmp_path)
    assert control.handle_line("task", state_wait_s=0.1)[0] == [
        "  no object_state received yet (is the simulation running?)"]
    # A prompt that just joined waits for the body's next task_status (one a second).
    control.task.on_objects(pa.array([0.2123, -0.0456, 0.0126, 0, 0, 0, 1, 0.16, 0.19, 0], type=pa.float32()))
    threading.Timer(0.3, control.task.on_status, (False, {"task": "cube_to_box", "seed": 3, "reply_to": ""})).start()
    lines = control.handle_line("task")[0]
    assert lines[0].startswith("  task cube_to_box, seed 3: cube at (")
    assert lines[1] == "  the cube is now at (212, -46, 13) mm: not in the box"
    # The cube lands in the box: one line of news, and `task` says so; the same status again says nothing more.
    control.task.on_status(True, {"task": "cube_to_box", "seed": 3, "reply_to": ""})
    control.task.on_status(True, {"task": "cube_to_box", "seed": 3, "reply_to": ""})
    assert news == ["  ★ the cube is in the box (task cube_to_box, seed 3)"]
    control.task.on_objects(pa.array([0.16, 0.19, 0.0175, 0, 0, 0, 1, 0.16, 0.19, 0], type=pa.float32()))
    assert control.handle_line("task")[0][1] == "  the cube is now at (160, 190, 18) mm: in the box"


def test_the_cube_landing_in_the_box_stops_a_policy_as_an_evaluated_episode_ends(tmp_path):
    control, _, news = task_control(tmp_path)
    told = []
    control.tell_policy = told.append
    control.task.on_objects(pa.array([0.2123, -0.0456, 0.0126, 0, 0, 0, 1, 0.16, 0.19, 0], type=pa.float32()))
    control.task.on_status(False, {"task": "cube_to_box", "seed": 3, "reply_to": ""})
    control.task.on_status(False, {"task": "cube_to_box", "seed": 3, "reply_to": ""})
    assert told == []
    control.task.on_objects(pa.array([0.16, 0.19, 0.0175, 0, 0, 0, 1, 0.16, 0.19, 0], type=pa.float32()))
    control.task.on_status(True, {"task": "cube_to_box", "seed": 3, "reply_to": ""})
    assert told == ["off"] and news == ["  ★ the cube is in the box (task cube_to_box, seed 3)"]
    control.task.on_status(False, {"task": "cube_to_box", "seed": 3, "reply_to": ""})  # jolted where it lies
    control.task.on_status(True, {"task": "cube_to_box", "seed": 3, "reply_to": ""})
    assert told == ["off"] and len(news) == 1


def test_expert_asks_the_expert_node_to_run_and_a_reset_stops_it(tmp_path):
    control, sent_cmds, news = task_control(tmp_path)
    told = []
    control.tell_expert = told.append
    assert control.handle_line("expert") == (["  → the expert is doing the task; any move you type takes over"], False)
    assert control.handle_line("reset 5")[0][0].startswith("  → laid out from seed 5")
    assert told == ["run", "stop"] and sent_cmds == ["reset 5"]
    # Its news comes on expert_status and is shown as it comes.
    control.on_event({"type": "INPUT", "id": "expert_status", "value": pa.array(["[expert] done: 9.1 s, 1 grasp(s)"])})
    assert news == ["  [expert] done: 9.1 s, 1 grasp(s)"]
    assert control.handle_line("expert now") == (["  'expert' takes no arguments, got 'expert now'"], False)


def test_without_a_task_reset_and_task_say_how_to_start_one(tmp_path):
    node, control = make_control(tmp_path, "zh", events=state_events())
    for line in ("reset", "reset 3", "task", "expert"):
        assert control.handle_line(line) == (["  没有任务:用 so101 teleop --task cube_to_box 启动"], False)
    assert sent(node) == []


def test_a_body_that_does_not_answer_a_reset_is_said_to_in_one_line(tmp_path, monkeypatch):
    from so101.prompt import task_link

    monkeypatch.setattr(task_link, "REPLY_WAIT_S", 0.2)
    control, sent_cmds, _ = task_control(tmp_path, answer=False)
    lines, _ = control.handle_line("reset")
    assert sent_cmds == ["reset"] and lines == ["  the simulation did not answer within 0.2 s"]
