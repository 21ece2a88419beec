"""The real arm's safety rules, each against `so101 fake-arm`'s emulated servos (their registers read back).

The contract itself (messages, units, clamping, bad commands, STOP) is tested with the
other bodies in tests/test_simulation_node.py, tests/test_dataflow.py and tests/test_faults.py.
"""

from __future__ import annotations

import json
import math
import os
import signal
import time
import uuid

import pytest

from so101.feetech.calibration import MOTOR_IDS, save_calibration
from so101.feetech.fake_arm import FakeArmProcess, calibrate_as_at_the_factory
from so101.bodies.real_arm import SO101Real
from tests.helpers.dataflow import TICK, DoraRun, body_environment, run_simulation_node, write_test_dataflow

pytestmark = pytest.mark.emulated_hardware  # the under-load check (tools/under_load.py) runs exactly these


def torque(arm: FakeArmProcess) -> list[int]:
    return [arm.read_register(servo_id, "Torque_Enable") for servo_id in MOTOR_IDS]


@pytest.fixture
def fake_arm(tmp_path, monkeypatch):
    """A calibrated emulated arm, the node's environment pointing at it."""
    with body_environment("real", tmp_path) as (env, arm):
        for name, value in env.items():
            monkeypatch.setenv(name, value)
        yield arm


def run_arm(monkeypatch, events, **env):
    return run_simulation_node(monkeypatch, events, body="real", **env)


# -- refusing to start -------------------------------------------------------------------------


@pytest.mark.parametrize("setting, message", [
    ("SO101_CALIBRATION", "SO101_CALIBRATION is empty: set it (the dataflow's env:, or so101 teleop --calibration) "
                          "to the arm's calibration file; make one with `so101 calibrate --port"),
    ("SO101_PORT", "SO101_PORT is empty: set it (the dataflow's env:, or so101 teleop --port) to the arm's serial port"),
])
def test_without_a_port_or_a_calibration_the_node_refuses_in_one_line(monkeypatch, capsys, fake_arm, setting, message):
    code, node = run_arm(monkeypatch, [TICK], **{setting: ""})
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("[arm] cannot start: ") and message in err
    assert torque(fake_arm) == [0] * 6 and "joint_state" not in node.outputs


@pytest.mark.parametrize("setting, message", [
    ("SO101_IMAGE_HZ", "the real arm has no camera: set SO101_IMAGE_HZ to 0"),
    ("SO101_FAST_STEPS", "the real arm has no fast mode (its goals ramp by the tick): set SO101_FAST_STEPS to 0"),
])
def test_pictures_and_fast_mode_are_refused_in_one_line(monkeypatch, capsys, fake_arm, setting, message):
    # Fast mode makes up ticks as fast as the bus answers: the goal ramp would outrun SO101_MAX_SPEED_DEG_S.
    code, node = run_arm(monkeypatch, [TICK], **{setting: "10"})
    err = capsys.readouterr().err
    assert code == 2 and err == f"[arm] cannot start: {message}\n"
    assert torque(fake_arm) == [0] * 6 and "joint_state" not in node.outputs


def test_a_calibration_of_another_arm_is_refused_and_torque_stays_off(monkeypatch, capsys, tmp_path, fake_arm):
    other = json.loads(open(os.environ["SO101_CALIBRATION"]).read())
    other["elbow_flex"]["homing_offset"] += 40
    other_file = tmp_path / "other_arm.json"
    other_file.write_text(json.dumps(other))
    code, _ = run_arm(monkeypatch, [TICK], SO101_CALIBRATION=str(other_file))
    err = capsys.readouterr().err
    assert code == 2
    assert (f"{other_file} does not match the arm on {fake_arm.port}: servo 3 (elbow_flex) has homing_offset "
            f"{other['elbow_flex']['homing_offset'] - 40}, the file says {other['elbow_flex']['homing_offset']}") in err
    assert err.count("\n") == 1
    assert torque(fake_arm) == [0] * 6


def test_a_missing_servo_is_named_and_nothing_starts(monkeypatch, capsys, tmp_path):
    with FakeArmProcess(ids=(1, 2, 3, 4, 5)) as arm:
        calibration = calibrate_as_at_the_factory(arm)
        with FakeArmProcess() as full:  # the gripper's calibration, from an arm that has one
            calibration.update({"gripper": calibrate_as_at_the_factory(full)["gripper"]})
        save_calibration(tmp_path / "c.json", calibration)
        code, _ = run_arm(monkeypatch, [TICK], SO101_PORT=arm.port, SO101_CALIBRATION=str(tmp_path / "c.json"))
        assert [arm.read_register(i, "Torque_Enable") for i in range(1, 6)] == [0] * 5
    err = capsys.readouterr().err
    assert code == 2
    assert f"servo 6 (gripper) does not answer on {arm.port}: check its power and cable, and that it has ID 6" in err


def test_a_port_that_does_not_exist_is_one_line(monkeypatch, capsys, fake_arm):
    code, _ = run_arm(monkeypatch, [TICK], SO101_PORT="/dev/no-such-adapter")
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert "cannot open the serial port /dev/no-such-adapter" in err and "so101 fake-arm" in err


# -- moving safely -----------------------------------------------------------------------------


def test_torque_goes_on_where_each_joint_stands_so_nothing_jumps(tmp_path):
    with FakeArmProcess() as arm:
        calibration = calibrate_as_at_the_factory(arm)
        # A goal left in the registers by an earlier program, far from where the joints stand.
        for servo_id in MOTOR_IDS:
            stops = arm.mechanics(servo_id)
            if stops.has_stops:
                arm.write_register(servo_id, "Goal_Position", stops.upper - calibration[list(calibration)[servo_id - 1]].homing_offset)
        before = [arm.physical_position(i) for i in MOTOR_IDS]
        with SO101Real(arm.port, calibration) as body:
            assert torque(arm) == [1] * 6
            for _ in range(10):
                body.step()
                time.sleep(0.02)
            after = [arm.physical_position(i) for i in MOTOR_IDS]
    assert after == before


def test_each_tick_moves_the_goal_by_at_most_the_speed_limit_times_the_tick(tmp_path):
    with FakeArmProcess() as arm:
        calibration = calibrate_as_at_the_factory(arm)
        with SO101Real(arm.port, calibration, max_speed_deg_s=90, time_step_s=0.02) as body:
            body.set_targets_deg([90, 0, 0, 0, 0, 45])
            goals = []
            for _ in range(60):
                body.step()
                goals.append(arm.read_register(1, "Goal_Position"))
                time.sleep(0.02)
            reached = body.joint_angles_deg()[0]
    steps_per_tick = 90 * 0.02 * 4096 / 360  # 1.8° = 20.48 steps
    moves = [later - earlier for earlier, later in zip(goals, goals[1:])]
    assert max(moves) <= math.ceil(steps_per_tick)
    assert goals[-1] - goals[0] == pytest.approx(90 * 4096 / 360 - steps_per_tick, abs=1)  # 50 ticks of the 60 were the ramp
    assert reached == pytest.approx(90.0, abs=0.1)


def test_goals_are_held_inside_the_calibrated_range_too(tmp_path):
    with FakeArmProcess() as arm:
        calibration = calibrate_as_at_the_factory(arm)
        pan = calibration["shoulder_pan"]
        # A range narrower than the URDF's ±110°, with the same middle: this arm's pan turns ±60°.
        half_steps = round(60 * 4096 / 360)
        narrow_min, narrow_max = round(pan.middle_steps) - half_steps, round(pan.middle_steps) + half_steps
        calibration["shoulder_pan"] = type(pan)(pan.id, pan.drive_mode, pan.homing_offset, narrow_min, narrow_max)
        arm.write_register(1, "Min_Position_Limit", narrow_min)
        arm.write_register(1, "Max_Position_Limit", narrow_max)
        with SO101Real(arm.port, calibration, max_speed_deg_s=360) as body:
            body.set_targets_deg([100, 0, 0, 0, 0, 45])
            for _ in range(60):
                body.step()
                time.sleep(0.02)
            assert arm.read_register(1, "Goal_Position") == narrow_max
            assert body.joint_angles_deg()[0] == pytest.approx(60.0, abs=0.1)  # not the URDF's 100°


# -- torque off on every way out ---------------------------------------------------------------


@pytest.mark.parametrize("ending", ["STOP", "Ctrl-C", "exception"])
def test_torque_goes_off_when_the_node_ends(monkeypatch, fake_arm, ending):
    from dora.testing import MockNode

    next_event = MockNode.__next__

    def ending_after_five_ticks(self):
        if len(self.outputs.get("joint_state", [])) == 5:
            assert torque(fake_arm) == [1] * 6
            if ending == "Ctrl-C":
                raise KeyboardInterrupt
            if ending == "exception":
                raise RuntimeError("a bug in the loop")
        return next_event(self)

    monkeypatch.setattr(MockNode, "__next__", ending_after_five_ticks)
    if ending == "exception":
        with pytest.raises(RuntimeError, match="a bug in the loop"):
            run_arm(monkeypatch, [TICK] * 10)
    else:
        code, _ = run_arm(monkeypatch, [TICK] * (5 if ending == "STOP" else 10))
        assert code == 0
    assert torque(fake_arm) == [0] * 6


def test_a_silent_servo_is_named_retried_and_not_published_as_fresh(monkeypatch, capsys, fake_arm):
    from dora.testing import MockNode

    next_event = MockNode.__next__
    ticks_seen = []

    def silent_for_three_ticks(self):
        event = next_event(self)
        if event.get("id") == "tick":
            ticks_seen.append(1)
            if len(ticks_seen) == 6:
                fake_arm.silence(3)
            if len(ticks_seen) == 9:
                fake_arm.answer(3)
        return event

    monkeypatch.setattr(MockNode, "__next__", silent_for_three_ticks)
    code, node = run_arm(monkeypatch, [TICK] * 20, SO101_BUS_RETRIES="5")  # the arm's default, stated: the test counts on it
    out = capsys.readouterr().out
    assert code == 0
    assert len(node.outputs["joint_state"]) == 20 - 3  # ticks 6-8 published nothing
    assert out.count("servo 3 did not answer to a sync read of Present_Position: check its power, its cable "
                     "and that its ID is 3; retrying, up to 5 times") == 1
    assert "the servos answer again after 3 failed read(s)" in out


@pytest.mark.parametrize("fault, message", [
    ("silence", "servo 4 did not answer to a sync read of Present_Position: check its power, its cable and that its ID is 4"),
    ("corrupt", "servo 4 sent a corrupted reply to a sync read of Present_Position"),
    ("mute_all", "servo 1 did not answer to a sync read of Present_Position"),
])
def test_past_its_retries_the_node_stops_with_one_line_and_torque_off(monkeypatch, capsys, fake_arm, fault, message):
    from dora.testing import MockNode

    next_event = MockNode.__next__

    def fault_after_five_ticks(self):
        if len(self.outputs.get("joint_state", [])) == 5:
            getattr(fake_arm, fault)(*(() if fault == "mute_all" else (4,)))
        return next_event(self)

    monkeypatch.setattr(MockNode, "__next__", fault_after_five_ticks)
    code, node = run_arm(monkeypatch, [TICK] * 40, SO101_BUS_RETRIES="3")
    err = capsys.readouterr().err
    assert code == 1
    assert len(node.outputs["joint_state"]) == 5
    assert err.startswith("[arm] stopping: ") and message in err and "still failing after 3 retries, torque off" in err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert torque(fake_arm) == [0] * 6  # the servos still hear the bus: the write reached them


def test_a_lost_port_ends_the_node_with_one_line(monkeypatch, capsys, fake_arm):
    from dora.testing import MockNode

    next_event = MockNode.__next__

    def unplugged_after_five_ticks(self):
        if len(self.outputs.get("joint_state", [])) == 5:
            fake_arm.close_port()
        return next_event(self)

    monkeypatch.setattr(MockNode, "__next__", unplugged_after_five_ticks)
    code, node = run_arm(monkeypatch, [TICK] * 20)
    captured = capsys.readouterr()
    assert code == 1
    assert len(node.outputs["joint_state"]) == 5
    assert captured.err.startswith(f"[arm] stopping: lost the serial port {fake_arm.port}")
    assert "check the USB cable and the servos' power supply" in captured.err and captured.err.count("\n") == 1
    # Nothing can reach the servos now: the node says so rather than claim torque is off.
    assert "could not confirm torque off" in captured.out and "switch the arm's power off" in captured.out


@pytest.mark.dataflow
@pytest.mark.parametrize("signal_number", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "Ctrl-C"])
def test_a_signal_to_the_running_node_switches_torque_off(tmp_path, signal_number):
    from tests.helpers.processes import command_line, processes_with_marker, wait_until_gone

    marker = uuid.uuid4().hex
    with body_environment("real", tmp_path) as (env, arm):
        dataflow = write_test_dataflow(tmp_path, sim_env={"SO101_LANG": "en", **env}, body="real")
        dora = DoraRun(dataflow, tmp_path / "dora.log", stop_after_s=60, SO101_TEST_RUN=marker)
        try:
            dora.wait_for("SO-101 loaded", timeout_s=60)
            assert torque(arm) == [1] * 6
            node = [pid for pid in processes_with_marker(marker) if "arm_node.py" in command_line(pid)]
            assert len(node) == 1
            os.kill(node[0], signal_number)
            deadline = time.monotonic() + 10
            while torque(arm) != [0] * 6 and time.monotonic() < deadline:
                time.sleep(0.05)
            assert torque(arm) == [0] * 6, dora.log()[-2000:]
        finally:
            dora.stop()
            left = wait_until_gone(marker)
    # The node's own log file: `dora run`'s console may drop the last lines of a node that exits on a signal.
    node_log = "".join(path.read_text() for path in tmp_path.glob("out/*/log_arm.jsonl"))
    assert "torque off on servos 1-6" in node_log
    assert "Traceback" not in dora.log() and "Traceback" not in node_log
    assert left == []


def test_a_ping_or_read_at_start_is_tried_again_after_a_lost_or_cut_short_reply():
    from so101.feetech.bus import BusLost, NoPort, ServoSilent
    from so101.feetech.checks import START_ATTEMPTS, at_start

    def answers_after(failures):
        tries = []

        def ask():
            tries.append(1)
            if len(tries) <= len(failures):
                raise failures[len(tries) - 1]
            return 2048
        return ask, tries

    ask, tries = answers_after([ServoSilent(2, False, "a read of Homing_Offset"), BusLost("cut short")])
    assert at_start(ask) == 2048 and len(tries) == 3
    ask, tries = answers_after([ServoSilent(2, False, "a read")] * START_ATTEMPTS)
    with pytest.raises(ServoSilent):
        at_start(ask)
    assert len(tries) == START_ATTEMPTS
    ask, tries = answers_after([NoPort("cannot open the serial port /dev/ttyACM0")])
    with pytest.raises(NoPort):  # no port is no lost packet: said at once
        at_start(ask)
    assert len(tries) == 1
    assert at_start(lambda: None) is None  # a ping nobody answers, START_ATTEMPTS times: None stands
