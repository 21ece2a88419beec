"""`so101 calibrate`, typed at by a script while `so101 fake-arm`'s emulated hand moves the joints."""

from __future__ import annotations

import json
import subprocess

import pytest

from so101.feetech.calibration import MOTOR_IDS, MOTOR_NAMES, load_calibration
from so101.feetech.fake_arm import FakeArmProcess
from so101.bodies.real_arm import SO101Real
from so101.leader.arm import SO101Leader
from tests.helpers.calibrate import Calibrate
from tests.helpers.dataflow import SO101, dora_env

pytestmark = pytest.mark.emulated_hardware  # the under-load check (tools/under_load.py) runs exactly these


@pytest.mark.parametrize("role", ["follower", "leader"])
def test_a_scripted_calibration_finds_the_emulated_arms_offsets_and_ranges(tmp_path, role):
    out = tmp_path / "arm.json"
    with FakeArmProcess() as arm:
        arm.write_register(1, "Torque_Enable", 1)  # left on by an earlier program: calibrate switches it off
        calibrate = Calibrate("--port", arm.port, "--out", str(out), *(["--leader"] if role == "leader" else []))
        calibrate.wait_for("Then press Enter.")
        assert [arm.read_register(i, "Torque_Enable") for i in MOTOR_IDS] == [0] * 6
        calibrate.enter()  # the emulated arm rests in the middle pose
        calibrate.wait_for("Press Enter when done.")
        calibrate.enter()  # too soon: nothing moved yet
        calibrate.wait_for("moved less than 100 steps")
        arm.sweep(duration_s=1.5)
        assert arm.wait_hand(timeout=10)
        calibrate.enter()
        code, output, err = calibrate.finish()
        assert code == 0, output + err
        registers = {i: {name: arm.read_register(i, name) for name in ("Homing_Offset", "Min_Position_Limit",
                                                                         "Max_Position_Limit", "Lock")}
                     for i in MOTOR_IDS}
        # The file drives the arm (or, from the leader, the body): at the middle pose every arm joint reads 0°.
        if role == "leader":
            with SO101Leader(arm.port, load_calibration(out, role="leader")) as leader:
                angles = leader.latest_deg
            assert all(arm.values_written(i, "Torque_Enable") == {0} for i in MOTOR_IDS)
        else:
            with SO101Real(arm.port, load_calibration(out)) as body:
                angles = body.joint_angles_deg()

    written = json.loads(out.read_text())
    assert list(written) == list(MOTOR_NAMES)
    # Worked out from the emulator's assembly (so101/feetech/fake_arm.py MECHANICAL_TABLE): the middle
    # pose reads 2047 after homing, so homing_offset = centre - 2047, and the range is the hard
    # stops in that frame; wrist_roll turns fully (0..4095), as LeRobot records it.
    centres = {1: 2048 + 310, 2: 2048 - 420, 3: 2048 + 190, 4: 2048 - 275, 5: 2048 + 530, 6: 2048 - 360}
    half_travel = {1: 1252, 2: 1138, 3: 1102, 4: 1081, 6: 626}  # the URDF ranges at 4096 steps per turn, halved
    for name, servo_id in zip(MOTOR_NAMES, MOTOR_IDS):
        offset = centres[servo_id] - 2047
        expected = {"id": servo_id, "drive_mode": 0, "homing_offset": offset,
                    "range_min": 0 if servo_id == 5 else centres[servo_id] - half_travel[servo_id] - offset,
                    "range_max": 4095 if servo_id == 5 else centres[servo_id] + half_travel[servo_id] - offset}
        assert written[name] == expected, name
        assert registers[servo_id] == {"Homing_Offset": offset, "Min_Position_Limit": expected["range_min"],
                                       "Max_Position_Limit": expected["range_max"], "Lock": 1}
    assert angles[:5] == pytest.approx([0.0] * 5, abs=0.1)
    use_it = (f"so101 teleop --leader {arm.port} --leader-calibration {out}" if role == "leader"
              else f"so101 teleop --body real --port {arm.port} --calibration {out}")
    assert f"Wrote {out}:" in output and use_it in output


def test_an_existing_file_is_kept_unless_forced_and_then_backed_up(tmp_path):
    out = tmp_path / "arm.json"
    out.write_text('{"kept": true}')
    with FakeArmProcess() as arm:
        refused = subprocess.run([str(SO101), "calibrate", "--port", arm.port, "--out", str(out)],
                                 capture_output=True, text=True, env=dora_env(SO101_LANG="en"), timeout=30)
        assert refused.returncode == 2
        assert refused.stderr == f"so101 calibrate: {out} exists: pass --force to replace it (the old one is kept as arm.json.bak)\n"
        calibrate = Calibrate("--port", arm.port, "--out", str(out), "--force")
        calibrate.wait_for("Then press Enter.")
        calibrate.enter()
        calibrate.wait_for("Press Enter when done.")
        arm.sweep(duration_s=1.0)
        assert arm.wait_hand(timeout=10)
        calibrate.enter()
        code, output, err = calibrate.finish()
    assert code == 0, output + err
    assert json.loads((tmp_path / "arm.json.bak").read_text()) == {"kept": True}
    assert set(json.loads(out.read_text())) == set(MOTOR_NAMES)


@pytest.mark.parametrize("ids, ending, message", [
    ((1, 2, 3, 4, 5), None, "so101 calibrate: servo 6 (gripper) does not answer on {port}"),
    ((1, 2, 3, 4, 5, 6), "eof", "so101 calibrate: the input ended before the calibration did; nothing was written to {out}"),
])
def test_failures_write_nothing_and_say_so_in_one_line(tmp_path, ids, ending, message):
    out = tmp_path / "arm.json"
    with FakeArmProcess(ids=ids) as arm:
        calibrate = Calibrate("--port", arm.port, "--out", str(out))
        if ending == "eof":
            calibrate.wait_for("Then press Enter.")
            calibrate.enter()
            calibrate.wait_for("Press Enter when done.")
            calibrate.end_input()
        code, output, err = calibrate.finish()
    assert code == 1
    assert message.format(port=arm.port, out=out) in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not out.exists()


def test_a_missing_port_is_one_line(tmp_path):
    result = subprocess.run([str(SO101), "calibrate", "--port", "/dev/no-such-adapter", "--out", str(tmp_path / "a.json")],
                            capture_output=True, text=True, env=dora_env(SO101_LANG="en"), timeout=30)
    assert result.returncode == 1
    assert result.stderr.strip().startswith("so101 calibrate: cannot open the serial port /dev/no-such-adapter")
    assert len(result.stderr.strip().splitlines()) == 1
