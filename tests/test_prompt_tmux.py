"""A person at a terminal: `so101 teleop --mode direct` in tmux, driven with send-keys, read with capture-pane."""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import time
from pathlib import Path

import pytest

from so101.runtime.display import virtual_display
from tests.helpers.dataflow import SO101
from tests.helpers.terminal import Terminal, calibrate_in_tmux, send_keys, start_teleop

pytestmark = [
    pytest.mark.person,
    pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux is not installed (.ci/run installs it)"),
]

TARGET_DEG = [-30.0, 45.0, -60.0, 30.0, 0.0]


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"


def test_a_person_drives_the_arm_from_the_prompt(tmp_path):
    terminal, poses_file, log_file = start_teleop(tmp_path, "zh")
    try:
        terminal.seen = terminal.wait_for_prompt(timeout_s=120).start()

        terminal.command("0 90", re.escape("  → 关节 0 (shoulder_pan) → 90°"))
        terminal.command("batch -30 45 -60 30 0", re.escape("  → 全关节 → [-30.0, 45.0, -60.0, 30.0, 0.0]°"))
        def state_reaches(target_deg: list[float]) -> None:
            # the arm needs about half a second to get there: `state` until it has (30 s at most)
            for _ in range(60):
                reached = terminal.command("state", r"  当前关节角度: \[(.*)\]°.*")
                angles = [float(word) for word in reached.group(1).split(",")]
                if all(abs(angle - target) <= 1.0 for angle, target in zip(angles, target_deg)):
                    return
                time.sleep(0.5)
            raise AssertionError(f"the arm did not reach {target_deg}: last state {angles}")

        state_reaches(TARGET_DEG)
        saved = terminal.command("save a", r"  → 姿态 'a' 已保存: \[(.*)\]°.*")
        saved_deg = [float(word) for word in saved.group(1).split(",")]
        assert all(abs(angle - target) <= 1.0 for angle, target in zip(saved_deg, TARGET_DEG)), saved_deg
        terminal.command("home", re.escape("  → 回零指令已发送"))
        state_reaches([0.0] * 5)
        terminal.command("go a", re.escape("  → 移动到姿态 'a'"))
        state_reaches(saved_deg)
        terminal.command("9 10", re.escape("  关节号范围 0-5(0-4 手臂,5 夹爪),收到 '9';格式:关节号 角度(如 '0 45')"))
        terminal.command("go b", re.escape("  未找到姿态 'b';已保存的姿态: a(用 'save 名字' 保存)"))
        terminal.command("0 nan", re.escape("  'nan' 不是角度:角度是十进制数字,单位度(如 45、-30.5)"))
        terminal.command("quit", re.escape("  再见"))
        terminal.wait_for(r"^数据流已停止\nTELEOP_EXIT=0$", timeout_s=60, after=terminal.seen)
        screen = terminal.screen()
    finally:
        terminal.close()

    assert "Traceback" not in screen, screen
    assert not re.search(r'^\s*\{".*"level"', screen, re.M), f"dora log lines in the prompt:\n{screen}"
    poses = json.loads(poses_file.read_text())
    assert list(poses) == ["a"]
    assert poses["a"]["joints_deg"] == saved_deg
    # every process dora started is gone
    spawned = [int(pid) for pid in re.findall(r"spawned node with pid (\d+)", log_file.read_text())]
    assert spawned, log_file.read_text()[-2000:]
    assert [pid for pid in spawned if _alive(pid)] == []


@pytest.mark.parametrize("key", ["C-c", "C-d"], ids=["Ctrl-C", "Ctrl-D"])
def test_ctrl_c_or_d_on_teleop_stops_everything_and_keeps_poses_and_history(tmp_path, key):
    terminal, poses_file, log_file = start_teleop(tmp_path, "en")
    try:
        end = terminal.wait_for_prompt(timeout_s=120).start()
        terminal.type_line("save b")
        end = terminal.wait_for(r"^  → pose 'b' saved: .*$", timeout_s=20, after=end).end()
        # Line editing: the up arrow brings back the last line, Enter runs it again.
        subprocess.run(["tmux", "send-keys", "-t", terminal.name, "Up", "Enter"], check=True)
        end = terminal.wait_for(r"^> save b\n  → pose 'b' saved: .*$", timeout_s=20, after=end).end()
        subprocess.run(["tmux", "send-keys", "-t", terminal.name, key], check=True)
        pressed_at = time.monotonic()
        exit_code = int(terminal.wait_for(r"^TELEOP_EXIT=(\d+)$", timeout_s=30, after=end).group(1))
        # Measured by polling the screen every 0.2 s: an upper bound on the real time.
        stopped_within_s = time.monotonic() - pressed_at
        screen = terminal.screen()
    finally:
        terminal.close()

    assert exit_code in (0, 130), screen
    assert stopped_within_s <= 3.0, f"{stopped_within_s:.1f} s from {key} to the shell prompt"
    assert "Traceback" not in screen, screen
    assert list(json.loads(poses_file.read_text())) == ["b"]
    assert (tmp_path / "history").read_text().splitlines()[-1] == "save b"  # kept for the next session
    spawned = [int(pid) for pid in re.findall(r"spawned node with pid (\d+)", log_file.read_text())]
    assert spawned, log_file.read_text()[-2000:]
    assert [pid for pid in spawned if _alive(pid)] == []


def test_closing_the_terminal_stops_everything_and_saves_the_episode_recording(tmp_path):
    # The terminal closing hangs teleop up: it stops the dataflow, and the recorder saves the episode.
    dataset_dir = tmp_path / "demos"
    terminal, _, log_file = start_teleop(tmp_path, "en", extra=f"--record {dataset_dir}")
    try:
        terminal.seen = terminal.wait_for_prompt(timeout_s=120).start()
        terminal.command("record closing time", r"  ● recording episode 0: .*")
        time.sleep(1.0)
    finally:
        terminal.close()  # tmux kill-session: the terminal is gone
    deadline = time.monotonic() + 40
    spawned = [int(pid) for pid in re.findall(r"spawned node with pid (\d+)", log_file.read_text())]
    assert spawned, log_file.read_text()[-2000:]
    while [pid for pid in spawned if _alive(pid)] and time.monotonic() < deadline:
        time.sleep(0.5)
    assert [pid for pid in spawned if _alive(pid)] == []
    from so101.dataset.reader import Dataset

    assert [episode.tasks for episode in Dataset.open(dataset_dir).episodes] == [("closing time",)]


@pytest.mark.skipif(shutil.which("Xvfb") is None, reason="Xvfb is not installed (Debian package xvfb)")
def test_no_dora_log_line_reaches_the_prompt_with_the_window_open(tmp_path):
    """The GUI on a software-rendered display is the busiest case: the prompt's input queues
    overflow there if anything does, and dora logs each drop on descriptor 1."""
    with virtual_display(tmp_path / "xvfb.log") as display:
        terminal, _, _ = start_teleop(tmp_path, "en", mode="gui", DISPLAY=display)
        try:
            end = terminal.wait_for_prompt(timeout_s=120).start()
            started = time.monotonic()
            sent = 0
            while time.monotonic() - started < 32:
                text = ("0 60", "0 -60", "state", "batch -30 45 -60 30 0", "home")[sent % 5]
                terminal.type_line(text)
                end = terminal.wait_for(rf"^> {re.escape(text)}\n  .*$", timeout_s=20, after=end).end()
                sent += 1
                time.sleep(1.0)
            terminal.type_line("quit")
            terminal.wait_for(r"^TELEOP_EXIT=0$", timeout_s=60, after=end)
            screen = terminal.screen()
        finally:
            terminal.close()
    assert sent >= 15
    assert "Traceback" not in screen, screen
    assert not re.search(r'\{"timestamp"|"level":', screen), f"dora log lines in the prompt:\n{screen}"
    # Every line on the screen is the prompt's own: banner, help, commands and their replies.
    prompt_log = (tmp_path / "prompt.log").read_text(errors="replace")
    assert all(line.startswith("{") for line in prompt_log.splitlines()), prompt_log[-2000:]


def test_teleop_drives_the_mujoco_body_with_the_same_prompt(tmp_path):
    terminal, poses_file, log_file = start_teleop(tmp_path, "en", body="mujoco")
    try:
        end = terminal.wait_for_prompt(timeout_s=120).start()
        terminal.type_line("0 60")
        end = terminal.wait_for(r"^> 0 60\n  → joint 0 \(shoulder_pan\) → 60°$", timeout_s=20, after=end).end()
        for _ in range(30):  # shoulder_pan carries no weight: MuJoCo's servo holds it within 1°
            time.sleep(0.5)
            terminal.type_line("state")
            reached = terminal.wait_for(r"^> state\n  joint angles now: \[([-\d.]+),.*$", timeout_s=20, after=end)
            end = reached.end()
            if abs(float(reached.group(1)) - 60.0) <= 1.0:
                break
        assert abs(float(reached.group(1)) - 60.0) <= 1.0, terminal.screen()
        terminal.type_line("save m")
        end = terminal.wait_for(r"^  → pose 'm' saved: \[.*$", timeout_s=20, after=end).end()
        # MuJoCo's servos sag under the arm's weight: once the arm stops, the prompt says where the tip is.
        terminal.type_line("xyz 200 0 150")
        landed = terminal.wait_for(r"^  the tip settled at \(([-\d.]+), ([-\d.]+), ([-\d.]+)\) mm, ([\d.]+) mm "
                                   r"from \(200, 0, 150\): the servos hold the joints a little off their goals$",
                                   timeout_s=60, after=end)
        end = landed.end()
        terminal.type_line("where")
        where = terminal.wait_for(r"^> where\n  tip at \(([-\d.]+), ([-\d.]+), ([-\d.]+)\) mm \(base frame\)$",
                                  timeout_s=20, after=end)
        end = where.end()
        terminal.type_line("quit")
        terminal.wait_for(r"^TELEOP_EXIT=0$", timeout_s=60, after=end)
        screen = terminal.screen()
    finally:
        terminal.close()
    assert "Traceback" not in screen, screen
    landed_mm = [float(value) for value in landed.groups()[:3]]
    assert float(landed.group(4)) == pytest.approx(math.dist(landed_mm, (200, 0, 150)), abs=0.1) and float(landed.group(4)) > 2.0
    assert [float(value) for value in where.groups()] == pytest.approx(landed_mm, abs=0.5)  # the arm stays where it settled
    assert "MuJoCo so101_new_calib.xml" in log_file.read_text()  # the MuJoCo node ran, not PyBullet's
    assert list(json.loads(poses_file.read_text())) == ["m"]
    spawned = [int(pid) for pid in re.findall(r"spawned node with pid (\d+)", log_file.read_text())]
    assert spawned and [pid for pid in spawned if _alive(pid)] == []


@pytest.mark.realtime
def test_a_person_without_an_arm_calibrates_the_emulated_one_and_drives_it(tmp_path):
    """The real arm's "done when": `so101 fake-arm`, `so101 calibrate` with its printed port, then
    `so101 teleop --body real` typed at as in the course; torque off after quit."""
    calibration_file = tmp_path / "my_arm.json"
    fake_arm = Terminal(f"{SO101} fake-arm", {"PATH": os.environ["PATH"], "SO101_LANG": "en"})
    terminal = None
    try:
        port = calibrate_in_tmux(fake_arm, calibration_file)

        terminal, poses_file, log_file = start_teleop(
            tmp_path, "en", body=f"real --port {port} --calibration {calibration_file}")
        end = terminal.wait_for_prompt(timeout_s=120).start()
        assert "the arm is ready (torque on)" in terminal.screen()

        def state_reaches(target_deg: list[float]) -> list[float]:
            nonlocal end
            for _ in range(40):
                time.sleep(0.5)
                terminal.type_line("state")
                reached = terminal.wait_for(r"^> state\n  joint angles now: \[(.*)\]°.*$", timeout_s=20, after=end)
                end = reached.end()
                angles = [float(word) for word in reached.group(1).split(",")]
                if all(abs(angle - target) <= 1.0 for angle, target in zip(angles, target_deg)):
                    return angles
            raise AssertionError(f"the arm did not reach {target_deg}: last state {angles}\n{terminal.screen()}")

        for line, target in (("0 90", [90.0, 0, 0, 0, 0]), ("batch -30 45 -60 30 0", TARGET_DEG)):
            terminal.type_line(line)
            end = terminal.wait_for(rf"^> {re.escape(line)}\n  → .*$", timeout_s=20, after=end).end()
            state_reaches(target)
        terminal.type_line("save a")
        end = terminal.wait_for(r"^  → pose 'a' saved: \[.*$", timeout_s=20, after=end).end()
        terminal.type_line("home")
        state_reaches([0.0] * 5)
        terminal.type_line("go a")
        state_reaches(TARGET_DEG)
        terminal.type_line("quit")
        terminal.wait_for(r"^TELEOP_EXIT=0$", timeout_s=60, after=end)
        screen = terminal.screen()
        fake_arm.type_line("status")
        status = fake_arm.wait_for(r"^id  joint.*\n((?:.*\n){5}.*)$", timeout_s=20, after=0)
        fake_arm.type_line("quit")
    finally:
        if terminal is not None:
            terminal.close()
        fake_arm.close()
    assert "Traceback" not in screen, screen
    assert "torque off on servos 1-6" in log_file.read_text()
    assert [row.split()[2] for row in status.group(0).splitlines()[1:]] == ["off"] * 6  # the emulator's own view
    assert list(json.loads(poses_file.read_text())) == ["a"]
    spawned = [int(pid) for pid in re.findall(r"spawned node with pid (\d+)", log_file.read_text())]
    assert spawned and [pid for pid in spawned if _alive(pid)] == []


def _pane_stty(terminal: Terminal) -> str:
    tty = subprocess.run(["tmux", "display", "-p", "-t", terminal.name, "#{pane_tty}"], capture_output=True,
                         text=True, check=True).stdout.strip()
    return subprocess.run(["stty", "-a", "-F", tty], capture_output=True, text=True, check=True).stdout


def test_jog_moves_the_arm_by_keys_and_xyz_reaches_a_point(tmp_path):
    """Mini project 7 and Cartesian targets, as a person does it: `jog`, W held, the limit, Tab
    and a sideways step, Esc; then `xyz 200 0 150` and `where`. The terminal is as it was."""
    terminal, _, _ = start_teleop(tmp_path, "en")
    try:
        end = terminal.wait_for_prompt(timeout_s=120).start()
        at_prompt = _pane_stty(terminal)
        terminal.type_line("jog")
        end = terminal.wait_for(r"^  jog mode \(a press moves, holding repeats\):$", timeout_s=20, after=end).end()
        terminal.wait_for(r"^\[joint\] step 2°  pan 0\.0 lift 0\.0", timeout_s=20, after=end)
        assert "icanon" in at_prompt or "-icanon" in at_prompt
        during = _pane_stty(terminal)
        assert " -icanon" in during and " -echo " in during  # raw keys while jogging
        send_keys(terminal, *["w"] * 5)  # five presses of 2°: shoulder_lift -10° raises the arm
        terminal.wait_for(r"^\[joint\] step 2°  pan 0\.0 lift -10\.0 ", timeout_s=20, after=end)
        send_keys(terminal, *["w"] * 80)  # held down: the terminal repeats the key
        terminal.wait_for(r"lift -100\.0 .*\| shoulder_lift at its limit -100\.0°$", timeout_s=30, after=end)
        send_keys(terminal, "-l", "+")
        send_keys(terminal, "a", "a")  # 5° a press: A turns the arm left, a negative shoulder_pan
        terminal.wait_for(r"^\[joint\] step 5°  pan -10\.0 ", timeout_s=20, after=end)
        send_keys(terminal, "Tab")
        first = terminal.wait_for(r"^\[cartesian\] step 10 mm .* tip \((-?\d+), (-?\d+), (-?\d+)\) mm", timeout_s=30, after=end)
        send_keys(terminal, "d", "d")  # two steps of 10 mm to the right: y falls by 20 mm
        y_before = int(first.group(2))
        deadline = time.monotonic() + 20
        while True:
            now = terminal.wait_for(r"^\[cartesian\] .* tip \((-?\d+), (-?\d+), (-?\d+)\) mm", after=end)
            if int(now.group(2)) <= y_before - 19 or time.monotonic() > deadline:
                break
            time.sleep(0.3)
        assert int(now.group(2)) == pytest.approx(y_before - 20, abs=1), terminal.screen()
        assert [int(now.group(i)) for i in (1, 3)] == pytest.approx([int(first.group(i)) for i in (1, 3)], abs=1)
        send_keys(terminal, "Escape")
        end = terminal.wait_for(r"^  left jog mode\n>$", timeout_s=20, after=end).start()
        assert _pane_stty(terminal) == at_prompt

        terminal.type_line("xyz 200 0 150")
        end = terminal.wait_for(r"^  → tip → \(200, 0, 150\) mm: joints \[.*\]°$", timeout_s=30, after=end).end()
        for _ in range(20):
            time.sleep(0.5)
            terminal.type_line("where")
            where = terminal.wait_for(r"^  tip at \((\S+), (\S+), (\S+)\) mm \(base frame\)$", timeout_s=20, after=end)
            end = where.end()
            reached = [float(where.group(i)) for i in (1, 2, 3)]
            if math.dist(reached, (200, 0, 150)) <= 5:
                break
        assert math.dist(reached, (200, 0, 150)) <= 5, reached
        terminal.type_line("xyz 1000 0 0")
        end = terminal.wait_for(r"^  \(1000, 0, 0\) mm is out of reach: the nearest point reached is .* not sent$",
                                timeout_s=30, after=end).end()
        for bad, reply in (("xyz 1 2", "  xyz format: xyz X Y Z"), ("xyz a 0 0", "  'a' is not a coordinate"),
                           ("xyz nan 0 0", "  'nan' is not a coordinate")):
            terminal.type_line(bad)
            end = terminal.wait_for(rf"^> {re.escape(bad)}\n{re.escape(reply)}.*$", timeout_s=20, after=end).end()
        terminal.type_line("jog")
        end = terminal.wait_for(r"^\[joint\] step 2°", timeout_s=20, after=end).end()
        send_keys(terminal, "C-c")  # Ctrl-C while jogging quits, as at the prompt
        terminal.wait_for(r"^TELEOP_EXIT=0$", timeout_s=60, after=end)
        screen = terminal.screen()
        after_exit = _pane_stty(terminal)
    finally:
        terminal.close()
    fresh = Terminal("sleep 30", {})
    try:
        time.sleep(0.5)
        untouched = _pane_stty(fresh)
    finally:
        fresh.close()
    assert after_exit == untouched  # the shell gets its terminal back as tmux made it
    assert "Traceback" not in screen, screen
    assert "pybullet build time" not in screen  # loading the kinematics writes its banner to the log


def test_the_dataflow_stopping_while_jogging_gives_the_terminal_back(tmp_path):
    from tests.helpers.dataflow import PROMPT_COMMAND, DoraRun, prompt_env, write_test_dataflow

    dora = DoraRun(write_test_dataflow(tmp_path, {"SO101_LANG": "en"}), tmp_path / "dora.log")
    terminal = None
    try:
        dora.wait_for("SO-101 loaded", timeout_s=60)
        terminal = Terminal(" ".join(PROMPT_COMMAND), prompt_env(tmp_path))
        end = terminal.wait_for_prompt(timeout_s=60).start()
        terminal.type_line("jog")
        end = terminal.wait_for(r"^\[joint\] step 2°", timeout_s=20, after=end).end()
        send_keys(terminal, "s", "s")
        terminal.wait_for(r"^\[joint\] step 2°  pan 0\.0 lift 4\.0 ", timeout_s=20)
        dora.stop()  # Ctrl-C to `dora run`: STOP reaches the prompt in the middle of jogging
        terminal.wait_for(r"^  the dataflow stopped: quitting\nTELEOP_EXIT=0$", timeout_s=30, after=end)
        after_exit = _pane_stty(terminal)
    finally:
        dora.stop()
        if terminal is not None:
            terminal.close()
    fresh = Terminal("sleep 30", {})
    try:
        time.sleep(0.5)
        assert after_exit == _pane_stty(fresh)
    finally:
        fresh.close()
