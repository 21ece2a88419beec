"""A dataset's joint units, said and never guessed (so101.dataset.units): the rule, LeRobot's own
arithmetic as the oracle, and the commands that read a dataset's joints saying or refusing in one line."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from so101.dataset.units import UNITS_KEY, UnitsError, joint_units
from so101.feetech.calibration import MOTOR_NAMES, MotorCalibration
from tests.helpers.dataflow import error_lines, run_so101

MADE = Path(__file__).parent / "data" / "lerobot_made"  # LeRobot's own: its values are within ±100, its meta says nothing
CALIBRATION = {name: MotorCalibration(id=index + 1, drive_mode=int(name == "elbow_flex"), homing_offset=0,
                                      range_min=700 + 50 * index, range_max=3300 - 40 * index)
               for index, name in enumerate(MOTOR_NAMES)}
WITHIN = np.array([[40.0, -90.0, 60.0, 10.0, -99.0, 55.0]])
BEYOND = np.array([[40.0, -120.5, 60.0, 10.0, 0.0, 55.0]])


@pytest.mark.parametrize("info, values, said, units, how", [
    ({UNITS_KEY: "degrees"}, WITHIN, None, "degrees", "joints in degrees (stated in the dataset)"),
    ({}, BEYOND, None, "degrees", "joints in degrees: a body joint reaches 120.5, beyond normalized's ±100"),
    ({}, WITHIN, "degrees", "degrees", "joints in degrees (said by --units)"),
    ({}, WITHIN, "normalized", "normalized", "joints in LeRobot's normalized units (said by --units), made degrees "
                                             "with the URDF's joint ranges as the calibrated ones"),
])
def test_the_units_come_from_the_meta_what_is_said_or_values_only_degrees_can_be(info, values, said, units, how):
    reading = joint_units(info, values, said)
    assert reading.units == units and reading.how.startswith(how)


@pytest.mark.parametrize("info, values, said, message", [
    ({}, WITHIN, None, "the dataset does not say its joints' units, and its values (within ±100) could be degrees or "
                       "LeRobot's normalized units: say --units degrees, or --units normalized (with --calibration FILE, "
                       "the recording follower's calibration)"),
    ({}, BEYOND, "normalized", "a body joint reaches 120.5, beyond ±100: these joints are degrees, not normalized"),
    ({UNITS_KEY: "degrees"}, WITHIN, "normalized", "the dataset says its joints are in degrees, not normalized: "
                                                   "leave --units out"),
    ({UNITS_KEY: "radians"}, WITHIN, None, "info.json says the joints are in 'radians': accepted degrees or normalized"),
])
def test_units_that_cannot_be_known_or_contradict_are_refused_in_one_line(info, values, said, message):
    with pytest.raises(UnitsError) as refused:
        joint_units(info, values, said)
    assert str(refused.value) == message


def test_normalized_joints_become_the_degrees_lerobot_would_have_written_with_the_same_calibration():
    """LeRobot's motor bus, per body joint: normalized n = (raw - min) / (max - min) * 200 - 100 (negated for a
    drive_mode 1 joint), degrees = (raw - (min + max) / 2) * 360 / 4095 (drive_mode ignored; this project's
    degrees turn with it: so101.feetech.calibration). Same raw, both ways."""
    reading = joint_units({}, WITHIN, "normalized", CALIBRATION, "follower.json")
    assert reading.how.endswith("made degrees with the calibrated ranges of follower.json")
    rng = np.random.default_rng(3)
    for name_index, name in enumerate(MOTOR_NAMES[:5]):
        motor = CALIBRATION[name]
        raw = rng.uniform(motor.range_min, motor.range_max, size=20)
        normalized = (raw - motor.range_min) / (motor.range_max - motor.range_min) * 200 - 100
        lerobot_deg = (raw - (motor.range_min + motor.range_max) / 2) * 360 / 4095
        frames = np.zeros((20, 6))
        frames[:, name_index] = -normalized if motor.drive_mode else normalized
        frames[:, 5] = 37.0
        ours = reading.as_degrees(frames)
        expected = -lerobot_deg if motor.drive_mode else lerobot_deg
        np.testing.assert_allclose(ours[:, name_index], expected, atol=0.05)  # 4096 steps a turn against 4095
        assert np.all(ours[:, 5] == 37.0)  # the gripper is 0..100 in both


@pytest.mark.parametrize("args, line", [
    (["replay", str(MADE), "--episode", "1", "--lang", "en"],
     f"so101 replay: {MADE}: the dataset does not say its joints' units, and its values (within ±100) could be degrees "
     "or LeRobot's normalized units: say --units degrees, or --units normalized (with --calibration FILE, the "
     "recording follower's calibration)"),
    (["dataset", str(MADE), "--plot", "1"], f"so101 dataset: {MADE}: the dataset does not say its joints' units"),
    (["dataset", str(MADE), "--units", "normalized", "--calibration", "{leader}"],
     "so101 dataset: {leader}: no calibration for shoulder_pan, shoulder_lift, elbow_flex, wrist_flex, wrist_roll, "
     "gripper (an SO-101 follower has"),
    (["cameras", "--fit", "front", "--from", str(MADE), "--units", "normalized", "--calibration", "{leader}"],
     "so101 cameras: {leader}: no calibration for shoulder_pan"),
    (["physics", "--fit", "--from", str(MADE), "--units", "normalized", "--calibration", "{leader}"],
     "so101 physics: {leader}: no calibration for shoulder_pan"),
    (["replay", str(MADE), "--units", "degrees", "--body", "real", "--physics", "varied"],
     "so101 replay: --physics sets a simulated body's servos: the real arm has its own"),
])
def test_a_command_reading_joints_it_cannot_use_refuses_in_one_line(tmp_path, args, line):
    leader = tmp_path / "other_arm.json"  # another arm's motor names
    leader.write_text(json.dumps({f"motor_{index}": {} for index in range(6)}))
    done = run_so101(*[arg.format(leader=leader) for arg in args])
    assert done.returncode == 2 and error_lines(done.stderr)[0].startswith(line.format(leader=leader)), done.stderr
    assert len(error_lines(done.stderr)) == 1, done.stderr


def test_the_dataset_summary_says_how_its_joints_are_read():
    unknown = run_so101("dataset", str(MADE))
    assert unknown.returncode == 0 and unknown.stdout.splitlines()[-1].startswith(
        "joints: the dataset does not say its joints' units"), unknown.stdout
    said = run_so101("dataset", str(MADE), "--units", "degrees")
    assert said.stdout.splitlines()[-1] == "joints in degrees (said by --units)", said.stdout


@pytest.mark.parametrize("stated, outcome", [
    ("degrees", ""),
    ("normalized", "whose joints are in LeRobot's normalized units: it would send them to the arm as degrees"),
    (None, "which does not say its joints' units, and its values could be degrees or LeRobot's normalized units: if "
           'degrees, say so in its meta/info.json ("so101_joint_units": "degrees")'),
])
def test_a_policy_is_driven_only_in_the_units_it_was_trained_in(tmp_path, stated, outcome):
    """The policy's train_config.json names its dataset: degrees drive the arm, anything else is one line."""
    import shutil

    from so101.policy.choice import joint_units_note

    dataset = tmp_path / "trained_on"
    shutil.copytree(MADE, dataset)
    if stated is not None:
        info_file = dataset / "meta" / "info.json"
        info_file.write_text(json.dumps({**json.loads(info_file.read_text()), UNITS_KEY: stated}))
    policy = tmp_path / "policy"
    policy.mkdir()
    (policy / "train_config.json").write_text(json.dumps({"dataset": {"root": str(dataset)}}))
    if not outcome:
        assert joint_units_note(policy) == ""
    else:
        with pytest.raises(ValueError, match=re.escape(outcome)) as refused:
            joint_units_note(policy)
        assert "\n" not in str(refused.value) and str(refused.value).startswith(f"the policy was trained on {dataset}")
    shutil.rmtree(dataset)
    assert joint_units_note(policy).startswith("note: the policy's joints are taken as degrees: its training dataset")
