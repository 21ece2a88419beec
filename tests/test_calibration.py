"""The real arm's calibration maths and LeRobot's JSON, checked against values worked out by hand."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import given, strategies as st

from so101.feetech.calibration import (
    CalibrationError,
    MotorCalibration,
    deg_to_steps,
    goal_steps,
    load_calibration,
    parse_calibration,
    parse_joint_signs,
    save_calibration,
    step_toward,
    steps_to_deg,
)

# A calibration as lerobot-calibrate writes it for an so101_follower (the values of one real-looking arm).
LEROBOT_FILE = {
    "shoulder_pan": {"id": 1, "drive_mode": 0, "homing_offset": -1535, "range_min": 760, "range_max": 3331},
    "shoulder_lift": {"id": 2, "drive_mode": 0, "homing_offset": 1408, "range_min": 817, "range_max": 3230},
    "elbow_flex": {"id": 3, "drive_mode": 0, "homing_offset": -1048, "range_min": 897, "range_max": 3112},
    "wrist_flex": {"id": 4, "drive_mode": 0, "homing_offset": -1185, "range_min": 860, "range_max": 3219},
    "wrist_roll": {"id": 5, "drive_mode": 0, "homing_offset": 1592, "range_min": 0, "range_max": 4095},
    "gripper": {"id": 6, "drive_mode": 0, "homing_offset": 1410, "range_min": 2031, "range_max": 3476},
}
GRIPPER_LOWER_DEG = math.degrees(-0.174533)  # so101_new_calib.urdf's gripper limits
GRIPPER_UPPER_DEG = math.degrees(1.74533)


@pytest.fixture
def calibration():
    return parse_calibration(json.loads(json.dumps(LEROBOT_FILE)))


def test_lerobots_file_is_read_as_it_is(tmp_path, calibration):
    path = tmp_path / "so101_follower.json"
    path.write_text(json.dumps(LEROBOT_FILE, indent=4))
    loaded = load_calibration(path)
    assert loaded == calibration
    assert loaded["elbow_flex"] == MotorCalibration(id=3, drive_mode=0, homing_offset=-1048, range_min=897, range_max=3112)


def test_saved_file_is_lerobots_format_and_reads_back(tmp_path, calibration):
    path = tmp_path / "calib" / "arm.json"
    save_calibration(path, calibration)
    assert json.loads(path.read_text()) == LEROBOT_FILE
    assert load_calibration(path) == calibration


@pytest.mark.parametrize("steps, expected_deg", [
    (2045.5, 0.0),  # the middle of 760..3331
    (3000, (3000 - 2045.5) * 360 / 4096),  # 83.8916015625
    (760, (760 - 2045.5) * 360 / 4096),
])
def test_arm_joint_is_zero_at_mid_range_with_4096_steps_per_turn(calibration, steps, expected_deg):
    assert steps_to_deg(0, steps, calibration["shoulder_pan"]) == pytest.approx(expected_deg, abs=1e-12)


def test_drive_mode_and_a_negative_sign_each_invert_and_together_cancel(calibration):
    motor = calibration["shoulder_pan"]
    inverted = MotorCalibration(1, 1, motor.homing_offset, motor.range_min, motor.range_max)
    assert steps_to_deg(0, 3000, inverted) == pytest.approx(-83.8916015625)
    assert steps_to_deg(0, 3000, motor, sign=-1) == pytest.approx(-83.8916015625)
    assert steps_to_deg(0, 3000, inverted, sign=-1) == pytest.approx(83.8916015625)


def test_gripper_range_maps_linearly_onto_the_urdf_gripper_range(calibration):
    gripper = calibration["gripper"]
    assert steps_to_deg(5, 2031, gripper) == pytest.approx(GRIPPER_LOWER_DEG)
    assert steps_to_deg(5, 3476, gripper) == pytest.approx(GRIPPER_UPPER_DEG)
    quarter = 2031 + (3476 - 2031) / 4
    assert steps_to_deg(5, quarter, gripper) == pytest.approx(GRIPPER_LOWER_DEG + (GRIPPER_UPPER_DEG - GRIPPER_LOWER_DEG) / 4)
    inverted = MotorCalibration(6, 1, 0, 2031, 3476)
    assert steps_to_deg(5, 2031, inverted) == pytest.approx(GRIPPER_UPPER_DEG)


@given(joint=st.integers(0, 5), steps=st.floats(0, 4095), drive_mode=st.integers(0, 1), sign=st.sampled_from([1, -1]))
def test_degrees_and_steps_are_inverses(joint, steps, drive_mode, sign):
    name = list(LEROBOT_FILE)[joint]
    raw = dict(LEROBOT_FILE[name], drive_mode=drive_mode)
    motor = MotorCalibration(**raw)
    assert deg_to_steps(joint, steps_to_deg(joint, steps, motor, sign), motor, sign) == pytest.approx(steps, abs=1e-6)


def test_goal_is_rounded_and_clamped_to_the_calibrated_range(calibration):
    motor = calibration["shoulder_lift"]
    assert goal_steps(1, 0.0, motor) == round((817 + 3230) / 2)
    assert goal_steps(1, 500.0, motor) == 3230
    assert goal_steps(1, -500.0, motor) == 817


def test_each_tick_moves_each_goal_by_at_most_the_step():
    assert step_toward((0.0, 0.0, 10.0), (90.0, -1.0, 10.0), 2.0) == (2.0, -1.0, 10.0)
    ramp = (0.0,)
    for _ in range(45):
        ramp = step_toward(ramp, (90.0,), 2.0)
    assert ramp == (90.0,)


@pytest.mark.parametrize("change, message", [
    (lambda doc: doc.pop("gripper"), "no calibration for gripper"),
    (lambda doc: doc["elbow_flex"].update(id=7), "elbow_flex.id = 7, but the SO-101 follower's elbow_flex is ID 3"),
    (lambda doc: doc["wrist_flex"].update(range_min=3300), "wrist_flex range 3300..3219 must satisfy"),
    (lambda doc: doc["shoulder_pan"].update(drive_mode=2), "shoulder_pan.drive_mode = 2: accepted 0 or 1"),
    (lambda doc: doc["shoulder_pan"].update(homing_offset="12"), "shoulder_pan.homing_offset = '12' is not a whole number"),
    (lambda doc: doc["shoulder_pan"].pop("range_max"), "shoulder_pan has no range_max"),
    (lambda doc: doc["shoulder_lift"].update(homing_offset=5000), "shoulder_lift.homing_offset = 5000 is outside ±2047"),
])
def test_a_wrong_file_gets_one_line_naming_what_is_wrong(tmp_path, change, message):
    document = json.loads(json.dumps(LEROBOT_FILE))
    change(document)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(document))
    with pytest.raises(CalibrationError) as raised:
        load_calibration(path)
    assert message in str(raised.value)
    assert "\n" not in str(raised.value)


def test_missing_and_unreadable_files_get_one_line(tmp_path):
    with pytest.raises(CalibrationError, match="no calibration file"):
        load_calibration(tmp_path / "none.json")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(CalibrationError, match="is not JSON"):
        load_calibration(tmp_path / "bad.json")


def test_joint_signs_take_six_ones_or_minus_ones():
    assert parse_joint_signs("1,1,-1,1,1,1") == (1, 1, -1, 1, 1, 1)
    assert parse_joint_signs("1 1 1 1 1 -1") == (1, 1, 1, 1, 1, -1)
    for bad in ("1,1,1", "1,1,1,1,1,2", "a,b,c,d,e,f", ""):
        with pytest.raises(ValueError, match="expected 6 values of 1 or -1"):
            parse_joint_signs(bad)
