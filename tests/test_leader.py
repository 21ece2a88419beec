"""The leader arm: its readings worked out by hand, its start-up and faults against `so101 fake-arm`'s
emulated servos (their registers read back), and every body following it under `dora run`."""

from __future__ import annotations

import json
import subprocess
import time
from contextlib import contextmanager

import pytest

from so101.bodies.registry import BODIES
from so101.feetech.calibration import MOTOR_IDS, MotorCalibration, save_calibration
from so101.feetech.fake_arm import FakeArmProcess, calibrate_as_at_the_factory
from so101.leader.arm import LeaderFailed, SO101Leader
from so101.leader.command import MOVED_DEG, Takeover, leader_command_deg, leader_values
from tests.helpers.dataflow import (
    PROMPT_COMMAND, DoraRun, body_environment, error_lines, prompt_env, run_so101, write_test_dataflow,
)

pytestmark = pytest.mark.emulated_hardware  # the under-load check (tools/under_load.py) runs exactly these

STEPS_PER_DEG = 4096 / 360


# -- the readings, by hand ---------------------------------------------------------------------


ARM_MOTOR = MotorCalibration(id=1, drive_mode=0, homing_offset=0, range_min=1000, range_max=3000)  # middle 2000
GRIPPER_MOTOR = MotorCalibration(id=6, drive_mode=0, homing_offset=0, range_min=2000, range_max=3000)


@pytest.mark.parametrize("joint_index, motor, steps, expected", [
    (0, ARM_MOTOR, 2512, 45.0),  # 512 steps past the middle: 512 x 360/4096
    (0, ARM_MOTOR, 2000, 0.0),
    (0, ARM_MOTOR, 1488, -45.0),
    (0, MotorCalibration(1, 1, 0, 1000, 3000), 2512, -45.0),  # drive_mode 1 turns the other way
    (0, ARM_MOTOR, 3500, 87.890625),  # past the calibrated range: held at its end (1000 x 360/4096)
    (5, GRIPPER_MOTOR, 2250, 25.0),  # the gripper: LeRobot's 0-100 across its range
    (5, MotorCalibration(6, 1, 0, 2000, 3000), 2250, 75.0),
    (5, GRIPPER_MOTOR, 1900, 0.0),
])
def test_a_leader_joint_reads_as_lerobot_reads_it(joint_index, motor, steps, expected):
    assert leader_values(joint_index, steps, motor) == pytest.approx(expected, abs=1e-9)


def test_the_command_is_in_degrees_with_the_gripper_on_the_followers_range():
    motors = [ARM_MOTOR] * 5 + [GRIPPER_MOTOR]
    present = {1: 2512, 2: 2000, 3: 1488, 4: 2256, 5: 2000, 6: 2250}
    # Gripper 25 of 0-100 on the follower's -10°..100°: -10 + 0.25 x 110 = 17.5°.
    assert leader_command_deg(present, motors) == pytest.approx((45.0, 0.0, -45.0, 22.5, 0.0, 17.5), abs=1e-9)


def test_a_typed_command_takes_over_until_the_leader_moves():
    takeover = Takeover()
    still = (10.0, 0.0, 0.0, 0.0, 0.0, 50.0)
    assert takeover.leader_drives(still)
    assert takeover.on_typed(still) is True  # the person is told once ...
    assert takeover.on_typed(still) is False  # ... not at every typed command
    nudged = (10.0 + MOVED_DEG - 0.1, 0.0, 0.0, 0.0, 0.0, 50.0)  # noise and drift: the typed pose holds
    assert not takeover.leader_drives(nudged) and takeover.typed
    moved = (10.0, 0.0, 0.0, 0.0, 0.0, 50.0 + MOVED_DEG)
    assert takeover.leader_drives(moved) and not takeover.typed
    assert takeover.leader_drives(still)


def test_typed_before_the_leaders_first_reading_holds_from_that_reading():
    takeover = Takeover()
    takeover.on_typed(None)
    first = (0.0,) * 6
    assert not takeover.leader_drives(first)
    assert not takeover.leader_drives((1.0,) + (0.0,) * 5)
    assert takeover.leader_drives((MOVED_DEG + 0.5,) + (0.0,) * 5)


# -- the leader on emulated servos --------------------------------------------------------------


@contextmanager
def emulated_leader(tmp_path):
    """An emulated SO-101 calibrated as a leader, and its calibration file."""
    with FakeArmProcess() as arm:
        calibration_file = tmp_path / "so101_leader.json"
        save_calibration(calibration_file, calibrate_as_at_the_factory(arm))
        yield arm, calibration_file


def start_leader(arm: FakeArmProcess, calibration_file, retries: int = 5) -> tuple[SO101Leader, list[str]]:
    from so101.feetech.calibration import load_calibration

    reports: list[str] = []
    leader = SO101Leader(arm.port, load_calibration(calibration_file, role="leader"),
                         calibration_name=str(calibration_file), retries=retries, report=reports.append)
    return leader, reports


def test_the_leader_reads_where_the_hand_put_it(tmp_path):
    with emulated_leader(tmp_path) as (arm, calibration_file):
        leader, _ = start_leader(arm, calibration_file)
        with leader:
            centre = arm.mechanics(1).centre
            arm.move_by_hand(1, centre + 512)  # 45° past the middle of shoulder_pan's travel
            gripper_low, _ = arm.mechanics(6).stops
            arm.move_by_hand(6, gripper_low)  # closed: 0 of LeRobot's 0-100, the follower's -10°
            reading = leader.poll()
    assert reading is not None
    assert reading[0] == pytest.approx(45.0, abs=0.1) and reading[5] == pytest.approx(-10.0, abs=0.1)
    assert reading[1:4] == pytest.approx([0.0] * 3, abs=0.1)


def test_torque_found_on_is_switched_off_and_said_and_never_switched_on(tmp_path):
    with emulated_leader(tmp_path) as (arm, calibration_file):
        for servo_id in (2, 3):
            arm.write_register(servo_id, "Torque_Enable", 1)  # left on by an earlier program
        leader, reports = start_leader(arm, calibration_file)
        with leader:
            for _ in range(20):
                leader.poll()
        assert [arm.read_register(i, "Torque_Enable") for i in MOTOR_IDS] == [0] * 6
        # The bus wrote Torque_Enable only to switch it off: never a 1, to any servo.
        assert {value for i in MOTOR_IDS for value in arm.values_written(i, "Torque_Enable")} == {0}
    assert reports == ["[leader] torque was on at servo(s) 2, 3: switched off (a leader is moved by hand)"]


def test_a_calibration_of_another_leader_is_refused_in_one_line(tmp_path):
    with emulated_leader(tmp_path) as (arm, calibration_file):
        other = json.loads(calibration_file.read_text())
        other["elbow_flex"]["homing_offset"] += 40
        other_file = tmp_path / "other_leader.json"
        other_file.write_text(json.dumps(other))
        with pytest.raises(LeaderFailed) as refused:
            start_leader(arm, other_file)
    message = str(refused.value)
    assert message.startswith(f"{other_file} does not match the leader on {arm.port}: servo 3 (elbow_flex) has "
                              f"homing_offset {other['elbow_flex']['homing_offset'] - 40}, the file says "
                              f"{other['elbow_flex']['homing_offset']}; make one with `so101 calibrate --leader --port")
    assert "\n" not in message


def test_no_leader_on_the_port_is_one_line():
    with FakeArmProcess() as arm:
        calibration = calibrate_as_at_the_factory(arm)
    with pytest.raises(LeaderFailed, match=r"^cannot open the serial port /nonexistent/ttyX: .*fake-arm"):
        SO101Leader("/nonexistent/ttyX", calibration)


def test_a_silent_leader_sends_nothing_and_is_said_once_then_again_when_it_answers(tmp_path):
    with emulated_leader(tmp_path) as (arm, calibration_file):
        leader, reports = start_leader(arm, calibration_file, retries=3)
        with leader:
            assert leader.poll() is not None
            arm.silence(3)
            readings = [leader.poll() for _ in range(10)]
            arm.answer(3)
            back = leader.poll()
    assert readings == [None] * 10  # never the last reading again
    assert back is not None
    assert len(reports) == 2
    assert reports[0].startswith("[leader] servo 3 did not answer to a sync read of Present_Position")
    assert reports[0].endswith("; 4 reads failed in a row: the body holds where it is, retrying every tick")
    assert reports[1] == "[leader] the leader answers again after 10 failed read(s)"


def test_a_glitch_shorter_than_the_retries_is_not_reported(tmp_path):
    with emulated_leader(tmp_path) as (arm, calibration_file):
        leader, reports = start_leader(arm, calibration_file, retries=3)
        with leader:
            arm.silence(2)
            assert [leader.poll() for _ in range(3)] == [None] * 3
            arm.answer(2)
            assert leader.poll() is not None
    assert reports == []


def test_an_unplugged_leader_is_said_once(tmp_path):
    with emulated_leader(tmp_path) as (arm, calibration_file):
        leader, reports = start_leader(arm, calibration_file)
        with leader:
            arm.close_port()
            readings = [leader.poll() for _ in range(5)]
    assert readings == [None] * 5
    assert len(reports) == 1 and reports[0].startswith("[leader] lost the serial port")
    assert reports[0].endswith("the body holds where it is: plug it back and start again")


@pytest.mark.parametrize("setting, message", [
    ("SO101_LEADER_PORT", "SO101_LEADER_PORT is empty: set it (the dataflow's env:, or so101 teleop --leader) "
                          "to the leader arm's serial port"),
    ("SO101_LEADER_CALIBRATION", "SO101_LEADER_CALIBRATION is empty: set it (the dataflow's env:, or so101 teleop "
                                 "--leader-calibration) to the leader's calibration file; make one with "
                                 "`so101 calibrate --leader --port"),
])
def test_the_node_without_a_port_or_a_calibration_refuses_in_one_line(monkeypatch, capsys, tmp_path, setting, message):
    import nodes.leader_node as leader_node

    with emulated_leader(tmp_path) as (arm, calibration_file):
        monkeypatch.setenv("SO101_LEADER_PORT", arm.port)
        monkeypatch.setenv("SO101_LEADER_CALIBRATION", str(calibration_file))
        monkeypatch.setenv(setting, "")
        monkeypatch.setattr(leader_node, "Node", lambda: pytest.fail("the node must not join the dataflow"))
        code = leader_node.main()
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert err.startswith("[leader] cannot start: ") and message in err


# -- every body follows the leader under dora run -------------------------------------------------------

pytest_dataflow = pytest.mark.dataflow
SETTLE_S = 2.0
# Where each body holds a still leader's pose: PyBullet's course motors within 2°; MuJoCo's soft
# MJCF servos sag under gravity (tests/test_dataflow.py measures about 2.5° at shoulder_lift); the
# emulated follower carries no load.
FOLLOW_TOLERANCE_DEG = {"pybullet": 2.0, "mujoco": 3.0, "real": 0.5}


def hand_pose(arm: FakeArmProcess, angles_deg: dict[int, float]) -> None:
    """The hand puts each joint (by servo ID) at an angle from the middle of its travel."""
    for servo_id, angle in angles_deg.items():
        arm.move_by_hand(servo_id, round(arm.mechanics(servo_id).centre + angle * STEPS_PER_DEG))


def leader_reading(arm: FakeArmProcess, calibration_file) -> tuple[float, ...]:
    """What the leader node reads now, from a second look at the same servos."""
    from so101.feetech.calibration import MOTOR_NAMES, load_calibration

    calibration = load_calibration(calibration_file, role="leader")
    present = {i: arm.read_register(i, "Present_Position") for i in MOTOR_IDS}
    return leader_command_deg(present, [calibration[name] for name in MOTOR_NAMES])


def states_between(samples, start: float, stop: float) -> list[list[float]]:
    return [state for t, state in samples if start < t < stop]


@pytest_dataflow
@pytest.mark.parametrize("body", list(BODIES))
def test_each_body_follows_the_leader_and_a_typed_command_takes_over_until_it_moves(tmp_path, body):
    record_file = tmp_path / "joint_state.json"
    pose_a = {1: 30.0, 2: -20.0, 3: 25.0, 4: 15.0}
    with emulated_leader(tmp_path) as (leader_arm, calibration_file), body_environment(body, tmp_path) as (body_env, _):
        leader_env = {"SO101_LEADER_PORT": leader_arm.port, "SO101_LEADER_CALIBRATION": str(calibration_file),
                      "SO101_LANG": "en"}
        dataflow = write_test_dataflow(tmp_path, {**body_env, "SO101_LANG": "en"}, record_file=record_file, body=body,
                                       leader_env=leader_env)
        dora = DoraRun(dataflow, tmp_path / "dora.log")
        prompt = None
        try:
            dora.wait_for("SO-101 leader ready", timeout_s=60)
            dora.wait_for("SO-101 loaded", timeout_s=60)
            marks = {}
            hand_pose(leader_arm, pose_a)
            marks["a"] = time.monotonic()
            expected_a = leader_reading(leader_arm, calibration_file)
            time.sleep(SETTLE_S)
            prompt = subprocess.Popen(PROMPT_COMMAND, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                      stderr=subprocess.STDOUT, text=True, env=prompt_env(tmp_path), cwd=tmp_path)
            time.sleep(1.0)
            marks["typed"] = time.monotonic()
            prompt.stdin.write("0 -45\n")
            prompt.stdin.flush()
            time.sleep(SETTLE_S)
            marks["moved"] = time.monotonic()
            hand_pose(leader_arm, {1: 40.0})  # 10° more than when the typed command came: the leader drives again
            expected_b = leader_reading(leader_arm, calibration_file)
            time.sleep(SETTLE_S)
            marks["end"] = time.monotonic()
            prompt.stdin.close()
            prompt_output = prompt.stdout.read()
            assert prompt.wait(20) == 0, prompt_output
        finally:
            if prompt is not None and prompt.poll() is None:
                prompt.kill()
            dora.stop()
        # The leader's Torque_Enable was never written to 1, whichever body followed it.
        assert {value for i in MOTOR_IDS for value in leader_arm.values_written(i, "Torque_Enable")} <= {0}
    log = dora.log()
    assert "Traceback" not in log, log[-3000:]
    samples = json.loads(record_file.read_text())["samples"]
    tolerance = FOLLOW_TOLERANCE_DEG[body]
    # The last state before each next step, at least a second after this one (every body settles in less).
    held_a = states_between(samples, marks["a"] + 1.0, marks["typed"])
    assert held_a and held_a[-1] == pytest.approx(expected_a[:5], abs=tolerance), body
    typed = states_between(samples, marks["typed"] + 1.0, marks["moved"])
    assert typed and typed[-1] == pytest.approx([-45.0, *expected_a[1:5]], abs=tolerance), body
    held_b = states_between(samples, marks["moved"] + 1.0, marks["end"])
    assert held_b and held_b[-1] == pytest.approx(expected_b[:5], abs=tolerance), body
    assert "a typed command took over; move the leader (more than 3°) to drive with it again" in prompt_output, prompt_output
    assert "the leader moved: it drives again" in prompt_output, prompt_output
    # The body logs the typed command, not each of the leader's hundred commands a second.
    assert log.count("all joint targets") == 0 and log.count("joint 0 target -> -45") == 1, log[-3000:]


@pytest_dataflow
def test_a_silent_or_unplugged_leader_leaves_the_body_where_it_is(tmp_path):
    record_file = tmp_path / "joint_state.json"
    with emulated_leader(tmp_path) as (leader_arm, calibration_file):
        leader_env = {"SO101_LEADER_PORT": leader_arm.port, "SO101_LEADER_CALIBRATION": str(calibration_file),
                      "SO101_LANG": "en"}
        dora = DoraRun(write_test_dataflow(tmp_path, {"SO101_LANG": "en"}, record_file=record_file, leader_env=leader_env),
                       tmp_path / "dora.log")
        try:
            dora.wait_for("SO-101 leader ready", timeout_s=60)
            dora.wait_for("SO-101 loaded", timeout_s=60)
            marks = {}
            hand_pose(leader_arm, {1: 20.0})
            time.sleep(SETTLE_S)
            leader_arm.silence(2)
            hand_pose(leader_arm, {1: 50.0})  # the hand moves on; nothing can be read
            marks["silent"] = time.monotonic()
            time.sleep(SETTLE_S)
            leader_arm.answer(2)
            marks["answers"] = time.monotonic()
            dora.wait_for("the leader answers again", timeout_s=10)
            time.sleep(SETTLE_S)
            leader_arm.close_port()
            marks["unplugged"] = time.monotonic()
            dora.wait_for("lost the serial port", timeout_s=10)
            time.sleep(SETTLE_S)
            marks["end"] = time.monotonic()
        finally:
            dora.stop()
    log = dora.log()
    samples = json.loads(record_file.read_text())["samples"]
    silent = states_between(samples, marks["silent"], marks["answers"])
    assert silent and all(state[0] == pytest.approx(20.0, abs=2.0) for state in silent)
    answered = states_between(samples, marks["answers"] + 1.0, marks["unplugged"])
    assert answered and answered[-1][0] == pytest.approx(50.0, abs=2.0)
    unplugged = states_between(samples, marks["unplugged"], marks["end"])
    assert unplugged and all(state[0] == pytest.approx(50.0, abs=2.0) for state in unplugged)
    assert log.count("reads failed in a row: the body holds where it is") == 1, log[-3000:]
    assert log.count("the leader answers again") == 1 and log.count("lost the serial port") == 1, log[-3000:]
    assert "Traceback" not in log, log[-3000:]


@pytest.mark.parametrize("options, message", [
    (["--leader", "/dev/ttyACM1"], "--leader PORT and --leader-calibration FILE go together (no leader? `so101 fake-arm` "
                                   "emulates one; `so101 calibrate --leader` makes the file)"),
    (["--leader-calibration", "leader.json"], "--leader PORT and --leader-calibration FILE go together"),
    (["--leader", "/dev/ttyACM0", "--leader-calibration", "leader.json", "--body", "real", "--port", "/dev/ttyACM0",
      "--calibration", "arm.json"], "--leader /dev/ttyACM0 is the follower's --port too: the two arms are on two serial ports"),
    (["--leader", "/dev/ttyACM1", "--leader-calibration", "missing.json"], "no calibration file {tmp}/missing.json"),
    (["--leader", "/dev/ttyACM1", "--leader-calibration", "not_json.json"], "{tmp}/not_json.json is not JSON"),
])
def test_teleop_refuses_a_leader_it_cannot_use_in_one_line_before_starting_anything(tmp_path, monkeypatch, capsys,
                                                                                      options, message):
    from so101.cli import main as cli

    monkeypatch.chdir(tmp_path)
    (tmp_path / "not_json.json").write_text("{")
    for name in ("leader.json", "arm.json"):
        with FakeArmProcess() as arm:
            save_calibration(tmp_path / name, calibrate_as_at_the_factory(arm))
    log_file = tmp_path / "dora.log"
    assert cli.main(["teleop", "--mode", "direct", "--lang", "en", "--log", str(log_file), *options]) == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith("so101 teleop: " + message.format(tmp=tmp_path)) and len(error.splitlines()) == 1
    assert not log_file.exists()  # no dataflow was started


@pytest_dataflow
def test_teleop_with_no_leader_on_the_port_says_so_in_one_line(tmp_path):
    """The leader node refuses before it joins; dora then fails the other nodes with backtraces, and
    teleop shows the node's one line, not those."""
    with FakeArmProcess() as arm:
        save_calibration(tmp_path / "leader.json", calibrate_as_at_the_factory(arm))
    result = run_so101("teleop", "--leader", "/dev/pts/nonexistent", "--leader-calibration", str(tmp_path / "leader.json"),
                       "--mode", "direct", "--lang", "en", "--log", str(tmp_path / "dora.log"))
    assert result.returncode == 1
    (line,) = error_lines(result.stderr)
    assert line.startswith("so101 teleop: [leader] cannot start: cannot open the serial port /dev/pts/nonexistent: ")
    assert line.endswith(f"({tmp_path / 'dora.log'})")
