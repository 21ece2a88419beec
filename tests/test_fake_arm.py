"""The emulated SO-101 bus (so101/feetech/fake_arm/), driven through Feetech's own SDK as a driver would.

The emulator runs in a process of its own (FakeArmProcess). Every test talks to it over its pseudo-terminal with scservo_sdk (PortHandler,
PacketHandler(0), GroupSyncRead/GroupSyncWrite) and checks values: the numbers a real
STS3215 would give, the timing of its motion, what the SDK reports for each fault.
`arm.read_register` / `physical_position` look inside where the bus cannot.
"""

from __future__ import annotations

import functools
import math
import os
import signal
import subprocess
import sys
import termios
import time
from pathlib import Path

import pytest
import serial
import scservo_sdk as scs

from so101.feetech.bus import FeetechBus, PortHandler
from so101.feetech.calibration import MOTOR_NAMES, steps_to_deg
from so101.feetech.fake_arm import (
    MECHANICAL_TABLE, MECHANICS, FakeArmProcess, calibrate_as_at_the_factory, joint_deg, physical_steps,
)
from so101.feetech.hand import eased_in, figure_eight_deg, parse_keyframes
from so101.feetech.sts3215 import decode_signed
from so101.robot import ACTUATED_JOINTS
from tests.helpers.processes import Lines

SO101 = Path(sys.executable).parent / "so101"
EXAMPLE_KEYFRAMES = Path(__file__).resolve().parent.parent / "examples" / "leader_wave.keyframes"
IDS = (1, 2, 3, 4, 5, 6)
JOINT_NAMES = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")

# Addresses from Feetech's STS memory table, written out here as the oracle
# (so101/feetech/sts3215.py holds the same numbers for the code).
MODEL_NUMBER, ID, BAUD_RATE, MIN_LIMIT, MAX_LIMIT, HOMING_OFFSET, OPERATING_MODE = 3, 5, 6, 9, 11, 31, 33
TORQUE_ENABLE, ACCELERATION, GOAL_POSITION, GOAL_VELOCITY, LOCK = 40, 41, 42, 46, 55
PRESENT_POSITION, PRESENT_VELOCITY, PRESENT_VOLTAGE, PRESENT_TEMPERATURE, MOVING = 56, 58, 62, 63, 66

pytestmark = pytest.mark.emulated_hardware  # the under-load check (tools/under_load.py) runs exactly these


@pytest.fixture
def arm():
    fake = FakeArmProcess()
    yield fake
    fake.close()


def open_bus(path: str):
    port = PortHandler(path)  # the SDK's, as the driver opens it (so101/feetech/bus.py)
    assert port.openPort()
    assert port.setBaudRate(1_000_000)
    return port, scs.PacketHandler(0)


@pytest.fixture
def bus(arm):
    port, packets = open_bus(arm.port)
    yield port, packets
    try:
        port.closePort()
    except Exception:
        pass


def sync_read(port, packets, address, size, ids=IDS):
    group = scs.GroupSyncRead(port, packets, address, size)
    for servo_id in ids:
        group.addParam(servo_id)
    result = group.txRxPacket()
    values = {i: group.getData(i, address, size) for i in ids if group.isAvailable(i, address, size)}
    return result, values, group


def sync_write(port, packets, address, size, values: dict[int, int]):
    group = scs.GroupSyncWrite(port, packets, address, size)
    for servo_id, value in values.items():
        data = [value & 0xFF, (value >> 8) & 0xFF][:size]
        assert group.addParam(servo_id, data)
    assert group.txPacket() == scs.COMM_SUCCESS


def eventually(check, timeout: float = 1.0):
    """A sync write gets no reply: the host cannot know when the servos have taken it."""
    deadline = time.monotonic() + timeout
    while not check():
        assert time.monotonic() < deadline, "not within the timeout"
        time.sleep(0.001)


def signed15(raw: int) -> int:
    return -(raw & 0x7FFF) if raw & 0x8000 else raw


# -- the assembled arm -------------------------------------------------------------------------


def test_mechanical_table_gives_each_joint_its_urdf_travel_off_centre():
    offsets = [offset for _, _, offset, _ in MECHANICAL_TABLE]
    assert [row[1] for row in MECHANICAL_TABLE] == list(JOINT_NAMES)
    assert len(set(offsets)) == 6 and all(abs(offset) >= 100 for offset in offsets)
    assert any(offset < 0 for offset in offsets) and any(offset > 0 for offset in offsets)
    for joint in ACTUATED_JOINTS:
        m = next(m for m in MECHANICS.values() if m.joint == joint.name)
        if joint.name == "wrist_roll":
            assert (m.lower, m.upper) == (None, None)
            continue
        travel_deg = (m.upper - m.lower) * 360 / 4096
        assert travel_deg == pytest.approx(joint.upper_deg - joint.lower_deg, abs=0.1)
        assert m.lower + m.upper == 2 * m.centre  # the middle of the travel
        assert 0 < m.lower < m.upper < 4095  # no stop range crosses the encoder's seam
    assert MECHANICS[6].upper - MECHANICS[6].lower == pytest.approx(110 / 360 * 4096, abs=1)  # gripper: -10°..100°


@pytest.mark.parametrize("servo_id, angle_deg, steps, read_back_deg", [
    (1, 0.0, 2358, 0.0),  # shoulder_pan's middle: 2048 + 310
    (1, 45.0, 2358 + 512, 45.0),  # 45° = 4096 / 8 steps
    (1, -90.0, 2358 - 1024, -90.0),
    (1, 200.0, 2358 + 1252, 1252 * 360 / 4096),  # past its stop (220° of travel = 2 x 1252 steps): held there
    (2, -30.0, 1628 - 4096 / 12, -30.0),
    (5, 90.0, 2578 + 1024, 90.0),
    (5, 180.0, (2578 + 2048) % 4096, -180.0),  # wrist_roll has no stops: round its turn
    (6, -10.0, 1062, -10.0),  # the gripper's -10°..100° across its stops 1688 ± 626
    (6, 100.0, 2314, 100.0),
    (6, 45.0, 1688, 45.0),
    (6, 17.5, 1062 + 0.25 * 1252, 17.5),
    (6, 150.0, 2314, 100.0),
])
def test_angles_are_placed_on_the_encoder_as_the_factory_calibrated_arm_reads_them(
    servo_id, angle_deg, steps, read_back_deg
):
    m = MECHANICS[servo_id]
    # Within 1e-3: the URDF's limits are radians, -10° is -0.174533 rad = -10.00000 3°.
    assert physical_steps(m, angle_deg) == pytest.approx(steps, abs=1e-3)
    assert joint_deg(m, steps) == pytest.approx(read_back_deg, abs=1e-3)


def test_degrees_agree_with_the_calibration_maths_over_the_bus():
    with FakeArmProcess() as fake:
        calibration = calibrate_as_at_the_factory(fake)
        poses = ((40.0, -60.0, 75.0, -20.0, 120.0, 80.0), (-100.0, 90.0, -90.0, 90.0, -150.0, -10.0))
        bus = FeetechBus(fake.port).open()
        try:
            for pose in poses:
                for servo_id, angle in zip(IDS, pose):
                    fake.move_by_hand(servo_id, round(physical_steps(MECHANICS[servo_id], angle)))
                present = bus.sync_read("Present_Position", IDS)
                reading = [steps_to_deg(i, present[i + 1], calibration[name]) for i, name in enumerate(MOTOR_NAMES)]
                # Whole steps on the encoder (0.088°); wrist_roll's calibrated middle is half a step off.
                assert reading == pytest.approx(pose, abs=0.1)
                assert [fake.joint_angle_deg(i) for i in IDS] == pytest.approx(pose, abs=0.1)
        finally:
            bus.close()


def test_ping_answers_model_777_for_ids_1_to_6_and_nothing_for_7(bus):
    port, packets = bus
    for servo_id in IDS:
        assert packets.ping(port, servo_id) == (777, scs.COMM_SUCCESS, 0)
    model, result, _ = packets.ping(port, 7)
    assert (model, result) == (0, scs.COMM_RX_TIMEOUT)


def test_power_up_registers(arm, bus):
    port, packets = bus
    for servo_id, m in MECHANICS.items():
        def read(address, size):
            read_n = packets.read1ByteTxRx if size == 1 else packets.read2ByteTxRx
            value, result, error = read_n(port, servo_id, address)
            assert (result, error) == (scs.COMM_SUCCESS, 0)
            return value

        assert read(MODEL_NUMBER, 2) == 777 and read(ID, 1) == servo_id and read(BAUD_RATE, 1) == 0
        assert (read(MIN_LIMIT, 2), read(MAX_LIMIT, 2), read(HOMING_OFFSET, 2)) == (0, 4095, 0)
        assert (read(OPERATING_MODE, 1), read(TORQUE_ENABLE, 1), read(LOCK, 1)) == (0, 0, 1)
        assert read(PRESENT_POSITION, 2) == read(GOAL_POSITION, 2) == m.centre  # resting at the middle
        assert (read(PRESENT_VOLTAGE, 1), read(PRESENT_TEMPERATURE, 1), read(MOVING, 1)) == (120, 30, 0)
        assert arm.read_register(servo_id, "Model_Number") == 777


def test_start_positions_choose_where_the_joints_rest():
    with FakeArmProcess(start_positions={1: 1500, 5: 10}) as fake:
        port, packets = open_bus(fake.port)
        result, values, _ = sync_read(port, packets, PRESENT_POSITION, 2)
        port.closePort()
    assert result == scs.COMM_SUCCESS
    assert values == {1: 1500, 2: 1628, 3: 2238, 4: 1773, 5: 10, 6: 1688}
    with pytest.raises(ValueError, match="outside its travel"):
        FakeArmProcess(start_positions={2: 100})  # below shoulder_lift's stop
    with pytest.raises(ValueError):
        FakeArmProcess(ids=(1, 7))


def test_single_register_writes_are_acknowledged_and_read_back(arm, bus):
    port, packets = bus
    assert packets.write2ByteTxRx(port, 4, GOAL_VELOCITY, 1234) == (scs.COMM_SUCCESS, 0)
    assert packets.write1ByteTxRx(port, 4, ACCELERATION, 50) == (scs.COMM_SUCCESS, 0)
    assert packets.read2ByteTxRx(port, 4, GOAL_VELOCITY) == (1234, scs.COMM_SUCCESS, 0)
    assert packets.read1ByteTxRx(port, 4, ACCELERATION) == (50, scs.COMM_SUCCESS, 0)
    assert arm.read_register(4, "Goal_Velocity") == 1234
    # Present_Position is the servo's to write: acknowledged, ignored.
    assert packets.write2ByteTxRx(port, 4, PRESENT_POSITION, 100) == (scs.COMM_SUCCESS, 0)
    assert packets.read2ByteTxRx(port, 4, PRESENT_POSITION)[0] == MECHANICS[4].centre
    # The test side writes too, signed registers as signed numbers.
    arm.write_register(4, "Goal_Velocity", -300)
    assert packets.read2ByteTxRx(port, 4, GOAL_VELOCITY)[0] == 300 | 0x8000
    with pytest.raises(ValueError, match="read-only"):
        arm.write_register(4, "Present_Position", 5)


def test_sync_read_of_all_six_present_positions(bus):
    result, values, _ = sync_read(*bus, PRESENT_POSITION, 2)
    assert result == scs.COMM_SUCCESS
    assert values == {i: MECHANICS[i].centre for i in IDS}


# -- motion --------------------------------------------------------------------------------


def test_sync_written_goals_are_reached_at_the_servo_speed():
    speed = 2000.0
    with FakeArmProcess(speed_steps_s=speed) as fake:
        port, packets = open_bus(fake.port)
        start = {i: MECHANICS[i].centre for i in IDS}
        goals = {i: start[i] + (400 if i % 2 else -400) for i in IDS}
        goals[1] = start[1] + 200  # servo 1 at its own Goal_Velocity: 1000 steps/s
        assert packets.write2ByteTxRx(port, 1, GOAL_VELOCITY, 1000)[0] == scs.COMM_SUCCESS
        sync_write(port, packets, TORQUE_ENABLE, 1, {i: 1 for i in IDS})
        t0 = time.monotonic()
        sync_write(port, packets, GOAL_POSITION, 2, goals)
        t1 = time.monotonic()
        time.sleep(0.08)
        t2 = time.monotonic()
        result, mid, _ = sync_read(port, packets, PRESENT_POSITION, 2)
        t3 = time.monotonic()
        assert result == scs.COMM_SUCCESS
        for i in IDS:
            v = 1000.0 if i == 1 else speed
            travelled = (mid[i] - start[i]) * (1 if goals[i] > start[i] else -1)
            # The goal took effect between t0 and a few ms after t1; the position was read between t2 and t3.
            assert v * (t2 - t1 - 0.010) - 1 <= travelled <= v * (t3 - t0) + 1, (i, travelled)
        velocity, result, _ = packets.read2ByteTxRx(port, 2, PRESENT_VELOCITY)
        assert signed15(velocity) == -2000  # servo 2 goes down
        assert packets.read1ByteTxRx(port, 2, MOVING)[0] == 1
        time.sleep(max(0.0, t0 + 0.2 + 0.03 - time.monotonic()))  # 400 steps at 2000/s, 200 at 1000/s
        result, final, _ = sync_read(port, packets, PRESENT_POSITION, 2)
        assert result == scs.COMM_SUCCESS and final == goals
        assert packets.read2ByteTxRx(port, 2, PRESENT_VELOCITY)[0] == 0
        assert packets.read1ByteTxRx(port, 2, MOVING)[0] == 0
        port.closePort()


def test_torque_off_the_motor_does_not_move(arm, bus):
    port, packets = bus
    centre = MECHANICS[3].centre
    assert packets.write2ByteTxRx(port, 3, GOAL_POSITION, centre + 300)[0] == scs.COMM_SUCCESS
    time.sleep(0.15)  # 300 steps take 0.1 s at the default speed
    assert packets.read2ByteTxRx(port, 3, PRESENT_POSITION)[0] == centre
    assert packets.read1ByteTxRx(port, 3, MOVING)[0] == 0
    assert packets.write1ByteTxRx(port, 3, TORQUE_ENABLE, 1)[0] == scs.COMM_SUCCESS
    time.sleep(0.15)
    assert packets.read2ByteTxRx(port, 3, PRESENT_POSITION)[0] == centre + 300


@pytest.mark.parametrize("offset", [300, -250])
def test_homing_offset_shifts_present_position_and_goals(arm, bus, offset):
    port, packets = bus
    physical = MECHANICS[1].centre  # 2358
    raw = offset if offset >= 0 else (-offset | 1 << 11)  # sign-magnitude, bit 11
    assert packets.write2ByteTxRx(port, 1, HOMING_OFFSET, raw)[0] == scs.COMM_SUCCESS
    assert arm.read_register(1, "Homing_Offset") == offset
    assert packets.read2ByteTxRx(port, 1, PRESENT_POSITION)[0] == physical - offset
    assert arm.physical_position(1) == physical  # the joint did not move
    # A goal is in the offset frame: goal 2048 puts the joint at 2048 + offset.
    assert packets.write2ByteTxRx(port, 1, GOAL_POSITION, 2048)[0] == scs.COMM_SUCCESS
    assert packets.write1ByteTxRx(port, 1, TORQUE_ENABLE, 1)[0] == scs.COMM_SUCCESS
    time.sleep(abs(physical - offset - 2048) / 3000 + 0.05)
    assert packets.read2ByteTxRx(port, 1, PRESENT_POSITION)[0] == 2048
    assert arm.physical_position(1) == 2048 + offset


def test_torque_enable_128_makes_the_present_position_read_2048(arm, bus):
    port, packets = bus
    assert packets.write1ByteTxRx(port, 4, TORQUE_ENABLE, 128)[0] == scs.COMM_SUCCESS
    assert packets.read2ByteTxRx(port, 4, PRESENT_POSITION)[0] == 2048
    assert arm.read_register(4, "Homing_Offset") == MECHANICS[4].centre - 2048 == -275
    assert arm.read_register(4, "Torque_Enable") == 0


def test_position_limits_clamp_goals(arm, bus):
    port, packets = bus
    assert packets.write2ByteTxRx(port, 1, MIN_LIMIT, 2000)[0] == scs.COMM_SUCCESS
    assert packets.write2ByteTxRx(port, 1, MAX_LIMIT, 2500)[0] == scs.COMM_SUCCESS
    assert packets.write1ByteTxRx(port, 1, TORQUE_ENABLE, 1)[0] == scs.COMM_SUCCESS
    assert packets.write2ByteTxRx(port, 1, GOAL_POSITION, 3000)[0] == scs.COMM_SUCCESS
    time.sleep(0.1)  # 142 steps from 2358 at 3000/s: 47 ms; 3000 would take 0.21 s
    assert packets.read2ByteTxRx(port, 1, PRESENT_POSITION)[0] == 2500
    assert packets.read2ByteTxRx(port, 1, GOAL_POSITION)[0] == 3000  # the register keeps what was written
    assert packets.write2ByteTxRx(port, 1, GOAL_POSITION, 100)[0] == scs.COMM_SUCCESS
    time.sleep(0.25)
    assert packets.read2ByteTxRx(port, 1, PRESENT_POSITION)[0] == 2000


def test_hard_stops_hold_the_motor_and_the_hand(arm, bus):
    port, packets = bus
    lower, upper = MECHANICS[2].lower, MECHANICS[2].upper  # shoulder_lift: 490..2766
    assert arm.move_by_hand(2, upper - 150) == upper - 150
    assert packets.write2ByteTxRx(port, 2, GOAL_POSITION, 4000)[0] == scs.COMM_SUCCESS
    assert packets.write1ByteTxRx(port, 2, TORQUE_ENABLE, 1)[0] == scs.COMM_SUCCESS
    time.sleep(150 / 3000 + 0.03)
    assert packets.read2ByteTxRx(port, 2, PRESENT_POSITION)[0] == upper
    time.sleep(0.05)
    assert packets.read2ByteTxRx(port, 2, PRESENT_POSITION)[0] == upper  # pushing against the stop, still
    assert packets.read1ByteTxRx(port, 2, MOVING)[0] == 0
    assert packets.read2ByteTxRx(port, 2, PRESENT_VELOCITY)[0] == 0
    # With torque on the hand cannot move it; with torque off it stops at the stops.
    assert arm.move_by_hand(2, 1000) == upper
    assert packets.write1ByteTxRx(port, 2, TORQUE_ENABLE, 0)[0] == scs.COMM_SUCCESS
    assert arm.move_by_hand(2, 0) == lower
    assert arm.move_by_hand(2, -100, relative=True) == lower
    assert arm.move_by_hand(2, 4095) == upper
    assert packets.read2ByteTxRx(port, 2, PRESENT_POSITION)[0] == upper
    # wrist_roll has no stops: its encoder wraps.
    assert arm.move_by_hand(5, 4000) == 4000
    assert arm.move_by_hand(5, 200, relative=True) == 104
    assert packets.read2ByteTxRx(port, 5, PRESENT_POSITION)[0] == 104


def test_power_cycle_keeps_only_eeprom_written_unlocked(arm, bus):
    port, packets = bus
    assert packets.write2ByteTxRx(port, 1, HOMING_OFFSET, 100)[0] == scs.COMM_SUCCESS  # Lock = 1: not saved
    assert packets.write1ByteTxRx(port, 2, LOCK, 0)[0] == scs.COMM_SUCCESS
    assert packets.write2ByteTxRx(port, 2, HOMING_OFFSET, 200)[0] == scs.COMM_SUCCESS  # saved
    # Goal_Position is still 1628, now 200 steps off the present 1428: torque would move the joint.
    assert packets.read2ByteTxRx(port, 2, GOAL_POSITION)[0] == MECHANICS[2].centre
    assert packets.write1ByteTxRx(port, 3, TORQUE_ENABLE, 1)[0] == scs.COMM_SUCCESS  # 3 holds where it is
    arm.power_cycle()
    assert packets.read2ByteTxRx(port, 1, HOMING_OFFSET)[0] == 0
    assert packets.read2ByteTxRx(port, 2, HOMING_OFFSET)[0] == 200
    assert (packets.read1ByteTxRx(port, 3, TORQUE_ENABLE)[0], packets.read1ByteTxRx(port, 2, LOCK)[0]) == (0, 1)
    assert packets.read2ByteTxRx(port, 2, GOAL_POSITION)[0] == MECHANICS[2].centre - 200  # = present again


def test_a_new_id_moves_the_servo(arm, bus):
    port, packets = bus
    assert packets.write1ByteTxRx(port, 6, ID, 9) == (scs.COMM_SUCCESS, 0)  # answered from the old ID
    assert packets.ping(port, 9) == (777, scs.COMM_SUCCESS, 0)
    assert packets.ping(port, 6)[1] == scs.COMM_RX_TIMEOUT
    assert arm.read_register(6, "ID") == 9


def test_a_servo_set_to_another_baud_rate_drops_off_the_bus(arm, bus):
    port, packets = bus
    assert packets.write1ByteTxRx(port, 4, BAUD_RATE, 1) == (scs.COMM_SUCCESS, 0)  # 500,000: answered, then gone
    assert packets.ping(port, 4)[1] == scs.COMM_RX_TIMEOUT
    assert packets.ping(port, 3)[0] == 777
    assert arm.read_register(4, "Baud_Rate") == 1


# -- the wire ------------------------------------------------------------------------------------

# READ id 1, address 56 (Present_Position), 2 bytes; checksum ~(1+4+2+56+2) & 0xFF = 0xBE.
READ_PRESENT_1 = bytes([0xFF, 0xFF, 0x01, 0x04, 0x02, 0x38, 0x02, 0xBE])


def reply_within(ser, seconds: float) -> bytes:
    deadline = time.monotonic() + seconds
    data = b""
    while time.monotonic() < deadline:
        data += ser.read(64)
        time.sleep(0.002)
    return data


def test_raw_packets_bad_checksum_ignored_partial_and_noisy_packets_answered(arm, bus):
    port, _ = bus
    ser = port.ser
    centre = MECHANICS[1].centre  # 2358 = 0x0936
    answer = bytes([0xFF, 0xFF, 0x01, 0x04, 0x00, 0x36, 0x09, (~(1 + 4 + 0 + 0x36 + 0x09)) & 0xFF])
    assert centre == 0x0936
    ser.write(READ_PRESENT_1[:-1] + b"\xbf")  # wrong checksum
    assert reply_within(ser, 0.05) == b""
    ser.write(READ_PRESENT_1)
    assert reply_within(ser, 0.05) == answer
    ser.write(READ_PRESENT_1[:3])  # a packet in two pieces
    time.sleep(0.01)
    ser.write(READ_PRESENT_1[3:])
    assert reply_within(ser, 0.05) == answer
    ser.write(b"\x00\x13\xff" + READ_PRESENT_1)  # noise before the header
    assert reply_within(ser, 0.05) == answer
    assert arm.stats()["bad_checksums"] == 1


# -- faults ---------------------------------------------------------------------------------------


def test_a_silent_servo_times_out_in_a_sync_read_after_the_others_answered(arm, bus):
    port, packets = bus
    arm.silence(3)
    result, values, group = sync_read(port, packets, PRESENT_POSITION, 2)
    assert result == scs.COMM_RX_TIMEOUT
    # The SDK stops at the first servo that fails: 1 and 2 are fresh, 3-6 have no data.
    assert values == {1: MECHANICS[1].centre, 2: MECHANICS[2].centre}
    # It still obeys.
    assert packets.write1ByteTxRx(port, 3, TORQUE_ENABLE, 1)[0] == scs.COMM_RX_TIMEOUT
    assert arm.read_register(3, "Torque_Enable") == 1
    arm.answer(3)
    port.ser.reset_input_buffer()
    assert sync_read(port, packets, PRESENT_POSITION, 2)[0] == scs.COMM_SUCCESS


def test_a_corrupt_servo_gives_rx_corrupt_and_leaves_the_later_replies_waiting(arm, bus):
    port, packets = bus
    arm.corrupt(2)
    assert packets.read2ByteTxRx(port, 2, PRESENT_POSITION)[1] == scs.COMM_RX_CORRUPT
    assert packets.read2ByteTxRx(port, 1, PRESENT_POSITION) == (MECHANICS[1].centre, scs.COMM_SUCCESS, 0)
    result, values, _ = sync_read(port, packets, PRESENT_POSITION, 2)
    assert result == scs.COMM_RX_CORRUPT and list(values) == [1]
    # Servos 3-6 answered; the SDK left their replies in the input buffer. Its next transaction
    # does not clear them (clearPort() flushes output only): a driver must reset_input_buffer().
    time.sleep(0.01)
    assert port.ser.in_waiting == 4 * 8
    arm.answer(2)


def test_mute_all_nobody_answers_but_everybody_obeys(arm, bus):
    port, packets = bus
    arm.mute_all()
    assert packets.ping(port, 1)[1] == scs.COMM_RX_TIMEOUT
    sync_write(port, packets, TORQUE_ENABLE, 1, {i: 1 for i in IDS})
    eventually(lambda: [arm.read_register(i, "Torque_Enable") for i in IDS] == [1] * 6)
    assert packets.write1ByteTxRx(port, 4, TORQUE_ENABLE, 0)[0] == scs.COMM_RX_TIMEOUT
    assert arm.read_register(4, "Torque_Enable") == 0
    assert set(arm.faults().values()) == {"muted"}
    arm.answer_all()
    assert packets.ping(port, 1) == (777, scs.COMM_SUCCESS, 0)


def test_close_port_is_an_unplugged_adapter(arm, bus):
    port, packets = bus
    assert packets.ping(port, 1)[1] == scs.COMM_SUCCESS
    arm.close_port()
    # The SDK's txPacket flushes first (tcdrain): termios.error, which is not an OSError.
    with pytest.raises((serial.SerialException, OSError, termios.error)):
        packets.read2ByteTxRx(port, 1, PRESENT_POSITION)
    assert port.is_using  # and the SDK's port stays "busy": every later call says COMM_PORT_BUSY
    with pytest.raises(serial.SerialException):
        port.ser.write(READ_PRESENT_1)
    with pytest.raises(serial.SerialException):
        port.ser.read(1)
    assert not os.path.exists(arm.port)
    with pytest.raises(serial.SerialException):
        serial.Serial(arm.port, 1_000_000, timeout=0)
    assert arm.read_register(1, "Present_Position") == MECHANICS[1].centre  # the servos are still here
    arm.close()
    arm.close()


def test_the_port_survives_the_client_closing_and_reopening_it(arm):
    for _ in range(2):
        port, packets = open_bus(arm.port)
        assert packets.ping(port, 5)[1] == scs.COMM_SUCCESS
        port.closePort()


# -- a hand -----------------------------------------------------------------------------------------


def test_sweep_moves_torque_off_joints_to_both_stops_and_back(arm, bus):
    port, packets = bus
    assert packets.write1ByteTxRx(port, 2, TORQUE_ENABLE, 1)[0] == scs.COMM_SUCCESS  # held
    # Long enough that the sampling below sees wrist_roll inside 100 steps of its seam: at 0.6 s the
    # hand crossed those 200 steps in about 12 ms, and one slow round of reads missed them.
    assert arm.sweep(duration_s=1.5) == (1, 3, 4, 5, 6)
    seen: dict[int, set[int]] = {i: set() for i in IDS}
    moving = set()
    while arm.hand_busy():
        result, values, _ = sync_read(port, packets, PRESENT_POSITION, 2)
        assert result == scs.COMM_SUCCESS
        for i, value in values.items():
            seen[i].add(value)
        moving |= {i for i in IDS if packets.read1ByteTxRx(port, i, MOVING)[0]}
        time.sleep(0.002)
    for i in (1, 3, 4, 6):
        m = MECHANICS[i]
        assert min(seen[i]) == m.lower and max(seen[i]) == m.upper, (i, min(seen[i]), max(seen[i]))
    assert min(seen[5]) < 100 and max(seen[5]) > 3995  # wrist_roll turned through the seam
    assert seen[2] == {MECHANICS[2].centre}
    assert moving >= {1, 3, 4, 6}
    result, values, _ = sync_read(port, packets, PRESENT_POSITION, 2)
    assert values == {i: MECHANICS[i].centre for i in IDS}  # back in the middle
    assert arm.wait_hand(timeout=0)


def test_torque_on_mid_sweep_the_joint_stops_following_the_hand(arm, bus):
    port, packets = bus
    arm.sweep(duration_s=1.0, ids=(1,))
    time.sleep(0.1)
    present = packets.read2ByteTxRx(port, 1, PRESENT_POSITION)[0]
    assert present < MECHANICS[1].centre - 50  # on its way to the lower stop
    # As a driver does: goal = present, then torque on.
    assert packets.write2ByteTxRx(port, 1, GOAL_POSITION, present)[0] == scs.COMM_SUCCESS
    assert packets.write1ByteTxRx(port, 1, TORQUE_ENABLE, 1)[0] == scs.COMM_SUCCESS
    time.sleep(0.1)
    assert abs(packets.read2ByteTxRx(port, 1, PRESENT_POSITION)[0] - present) <= 3  # moved with the hand until torque
    assert not arm.hand_busy()


# -- a scripted hand: the emulator as a leader arm -------------------------------------------------------

# The fastest any figure-eight angle changes with a 2 s loop: the gripper, 40° x 2π/2 s ≈ 126°/s.
FIGURE_EIGHT_2S_TOP_DEG_S = 130.0


def expected_between(script, started: tuple[float, float], read: tuple[float, float], top_deg_s: float):
    """What `script` says for a reading taken between read[0] and read[1] of a hand started between
    started[0] and started[1] (time.monotonic), and how far off it can be: the script's top speed
    over half that window, plus the encoder's step."""
    earliest, latest = read[0] - started[1], read[1] - started[0]
    return script((earliest + latest) / 2), top_deg_s * (latest - earliest) / 2 + 0.1


def read_angles(bus: FeetechBus, calibration) -> tuple[tuple[float, ...], float, float]:
    """The six angles as a leader reads them (one SYNC READ), and the clock before and after it."""
    before = time.monotonic()
    present = bus.sync_read("Present_Position", IDS)
    after = time.monotonic()
    angles = tuple(steps_to_deg(i, present[i + 1], calibration[name]) for i, name in enumerate(MOTOR_NAMES))
    return angles, before, after


@pytest.fixture
def leader():
    """An emulated arm calibrated as at the factory, a FeetechBus on it, and the calibration."""
    with FakeArmProcess() as fake:
        calibration = calibrate_as_at_the_factory(fake)
        bus = FeetechBus(fake.port).open()
        try:
            yield fake, bus, calibration
        finally:
            bus.close()


def test_torque_off_joints_follow_the_figure_eight_read_over_the_bus_and_a_held_one_does_not(leader):
    fake, bus, calibration = leader
    bus.write(2, "Torque_Enable", 1)  # shoulder_lift held by its motor (Goal_Position = present)
    period_s, ease_s = 2.0, 0.3
    script = eased_in(lambda t_s: figure_eight_deg(t_s, period_s), (0.0, 0.0, 0.0, 0.0, 0.0, 45.0), ease_s)
    started_before = time.monotonic()
    assert fake.play_hand(functools.partial(figure_eight_deg, period_s=period_s), None, ease_s=ease_s) == (1, 3, 4, 5, 6)
    started_after = time.monotonic()
    samples, velocities = 0, 0
    pan_seen = []
    while time.monotonic() < started_after + 1.6:
        angles, before, after = read_angles(bus, calibration)
        expected, tolerance = expected_between(
            script, (started_before, started_after), (before, after), FIGURE_EIGHT_2S_TOP_DEG_S
        )
        for index in (0, 2, 3, 4, 5):
            assert angles[index] == pytest.approx(expected[index], abs=tolerance), (index, before - started_after)
        assert angles[1] == 0.0  # held at its middle
        pan_seen.append(angles[0])
        samples += 1
        if before - started_after > ease_s:  # Present_Velocity: the figure eight's own rate, in steps/s
            before = time.monotonic()
            raw = bus.read(1, "Present_Velocity")
            after = time.monotonic()
            earliest, latest = before - started_after, after - started_before
            omega = 2 * math.pi / period_s
            rate_steps_s = 30.0 * omega * math.cos(omega * (earliest + latest) / 2) * 4096 / 360
            change_steps_s2 = 30.0 * omega**2 * 4096 / 360  # how fast that rate changes
            assert decode_signed(raw, 15) == pytest.approx(rate_steps_s, abs=change_steps_s2 * (latest - earliest) / 2 + 2)
            velocities += 1
        time.sleep(0.005)
    assert samples > 50 and velocities > 20
    assert max(pan_seen) > 25.0 and min(pan_seen) < -25.0  # it went round the loop: pan 30° each way
    assert fake.hand_busy()  # a figure eight goes on ...
    assert not fake.wait_hand(timeout=0.05)
    assert bus.sync_read("Moving", (1, 2)) == {1: 1, 2: 0}
    assert {value for i in IDS for value in fake.values_written(i, "Torque_Enable")} == {1}  # the test's own write


def test_keyframes_start_where_the_joints_stand_and_the_last_is_held(leader):
    fake, bus, calibration = leader
    fake.move_by_hand(1, round(physical_steps(MECHANICS[1], -10.0)))
    keyframes = parse_keyframes("0.3  20 -20 30 0 90 100\n0.6  -20 10 -30 15 -90 -10\n", "test")
    script = eased_in(keyframes.at, (-10.0, 0.0, 0.0, 0.0, 0.0, 45.0), keyframes.times_s[0])
    started_before = time.monotonic()
    fake.play_hand(keyframes.at, keyframes.duration_s, ease_s=keyframes.times_s[0])
    started_after = time.monotonic()
    angles, before, after = read_angles(bus, calibration)
    # The hand starts from where the joints stood and reaches the first keyframe by 0.3 s: the
    # fastest leg, wrist_roll's 90° in 0.3 s on a smoothstep, peaks at 450°/s.
    expected, tolerance = expected_between(script, (started_before, started_after), (before, after), 450.0)
    assert angles == pytest.approx(expected, abs=tolerance)
    if after - started_before < 0.05:  # read at once, as it nearly always is: barely moved yet
        assert angles[0] == pytest.approx(-10.0, abs=1.0) and angles[5] == pytest.approx(45.0, abs=1.5)
    assert fake.hand_busy()
    assert fake.wait_hand(timeout=2.0)
    angles, _, _ = read_angles(bus, calibration)
    assert angles == pytest.approx((-20.0, 10.0, -30.0, 15.0, -90.0, -10.0), abs=0.1)
    time.sleep(0.1)
    assert read_angles(bus, calibration)[0] == angles  # held: nothing moves it any more
    assert (bus.read(1, "Moving"), bus.read(1, "Present_Velocity")) == (0, 0)


def test_hold_lets_go_where_the_joints_stand(leader):
    fake, bus, calibration = leader
    script = functools.partial(figure_eight_deg, period_s=2.0)

    started_before = time.monotonic()
    fake.play_hand(script, None, ease_s=0.0)
    started = started_before, time.monotonic()
    time.sleep(0.3)  # on its way: pan ≈ 30 sin(0.3π) ≈ 24°
    stopping = time.monotonic()
    assert fake.stop_hand() == IDS
    stopped = time.monotonic()
    held, _, _ = read_angles(bus, calibration)
    # Let go where the script had them when the hand stopped: no jump back, no further.
    expected, tolerance = expected_between(script, started, (stopping, stopped), FIGURE_EIGHT_2S_TOP_DEG_S)
    assert held == pytest.approx(expected, abs=tolerance)
    assert held[0] > 15.0
    time.sleep(0.2)
    assert read_angles(bus, calibration)[0] == held
    assert bus.sync_read("Moving", IDS) == bus.sync_read("Present_Velocity", IDS) == {i: 0 for i in IDS}
    assert not fake.hand_busy() and fake.wait_hand(timeout=0)
    assert fake.stop_hand() == ()  # nothing left to let go


def test_time_scale_runs_the_emulators_clock_faster_than_the_wall_clock():
    with FakeArmProcess(time_scale=4.0) as fake:
        assert fake.sweep(duration_s=2.0) == IDS
        time.sleep(0.6)  # at least 2.4 s of the emulator's clock, however late the sleep ends
        assert not fake.hand_busy()
        assert [fake.physical_position(i) for i in IDS] == [MECHANICS[i].centre for i in IDS]  # the sweep's end
    with pytest.raises(ValueError, match="time_scale must be positive"):
        FakeArmProcess(time_scale=0.0)


def five_angles(t_s: float) -> tuple[float, ...]:
    return (0.0,) * 5


def a_nan_angle(t_s: float) -> tuple[float, ...]:
    return (0.0, 0.0, 0.0, float("nan"), 0.0, 0.0)


def test_a_new_hand_takes_over_and_a_script_must_give_six_finite_angles(arm):
    arm.play_hand(figure_eight_deg)
    assert arm.sweep(duration_s=0.2) == IDS  # the sweep takes the joints from the figure eight
    assert arm.wait_hand(timeout=1.0)
    assert [arm.physical_position(i) for i in IDS] == [MECHANICS[i].centre for i in IDS]  # the sweep's end
    for script in (five_angles, a_nan_angle):
        with pytest.raises(ValueError, match="expected 6 finite angles"):
            arm.play_hand(script)
    with pytest.raises(ValueError, match="duration_s must be 0 or more"):
        arm.play_hand(figure_eight_deg, -1.0)
    assert not arm.hand_busy()


# -- the write log ----------------------------------------------------------------------------------------


def test_values_written_records_what_the_bus_wrote_and_not_the_api(arm, bus):
    port, packets = bus
    assert packets.write1ByteTxRx(port, 1, TORQUE_ENABLE, 0)[0] == scs.COMM_SUCCESS
    assert packets.write1ByteTxRx(port, 1, TORQUE_ENABLE, 128)[0] == scs.COMM_SUCCESS  # taken as a calibration, still written
    arm.write_register(1, "Torque_Enable", 1)  # the test's own: not the bus's
    assert arm.values_written(1, "Torque_Enable") == {0, 128}
    sync_write(port, packets, GOAL_POSITION, 2, {1: 2000, 2: 2100})
    eventually(lambda: arm.values_written(2, "Goal_Position") == {2100})
    assert arm.values_written(1, "Goal_Position") == {2000}
    assert packets.regWriteTxRx(port, 3, GOAL_POSITION, 2, [0x34, 0x12])[0] == scs.COMM_SUCCESS
    assert arm.values_written(3, "Goal_Position") == frozenset()  # held until ACTION
    assert packets.action(port, 3) == scs.COMM_SUCCESS
    assert arm.values_written(3, "Goal_Position") == {0x1234}
    # One write over Goal_Position and Goal_Time (42-45) counts for both; half a register for neither.
    assert packets.writeTxRx(port, 4, GOAL_POSITION, 4, [0x00, 0x08, 0x10, 0x00])[0] == scs.COMM_SUCCESS
    assert packets.write1ByteTxRx(port, 4, GOAL_POSITION + 1, 0x09)[0] == scs.COMM_SUCCESS
    assert (arm.values_written(4, "Goal_Position"), arm.values_written(4, "Goal_Time")) == ({0x800}, {0x10})
    assert packets.write2ByteTxRx(port, 4, GOAL_VELOCITY, 300 | 0x8000)[0] == scs.COMM_SUCCESS
    assert arm.values_written(4, "Goal_Velocity") == {-300}  # signed registers decoded, as read_register does
    assert arm.values_written(5, "Torque_Enable") == frozenset()
    with pytest.raises(KeyError):
        arm.values_written(1, "Speed")


# -- performance -------------------------------------------------------------------------------------


def test_a_sync_read_is_answered_in_a_few_milliseconds_and_idle_costs_nothing(arm, bus):
    port, packets = bus
    group = scs.GroupSyncRead(port, packets, PRESENT_POSITION, 2)
    for i in IDS:
        group.addParam(i)
    times = []
    for _ in range(50):
        t = time.perf_counter()
        assert group.txRxPacket() == scs.COMM_SUCCESS
        times.append(time.perf_counter() - t)
    times.sort()
    assert times[len(times) // 2] < 0.003, times  # ~0.4 ms here; the SDK's own timeout is 34 ms
    served = arm.packets_served
    cpu = time.process_time()
    time.sleep(0.3)
    assert time.process_time() - cpu < 0.03  # the emulator blocks in select
    assert arm.packets_served == served


# -- the command line -----------------------------------------------------------------------------------


@pytest.fixture
def start_cli():
    started = []

    def start(*options, stdin=subprocess.PIPE):
        process = subprocess.Popen(
            [str(SO101), "fake-arm", *options], stdin=stdin, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            env=dict(os.environ, SO101_LANG="en"),
        )
        started.append(process)
        lines = Lines(process.stdout)
        return process, lines, lines.next()

    yield start
    for process in started:
        if process.poll() is None:
            process.kill()
        process.wait(timeout=10)
        for stream in (process.stdin, process.stdout, process.stderr):
            if stream:
                stream.close()


def test_cli_prints_the_port_and_serves_it_and_takes_commands(start_cli):
    process, lines, port_path = start_cli("--silent", "6")
    assert port_path.startswith("/dev/pts/")
    about = lines.next()
    assert "emulated SO-101" in about and "1,000,000 baud" in about and "help" in about and "gravity" in about
    port, packets = open_bus(port_path)
    assert packets.ping(port, 1) == (777, scs.COMM_SUCCESS, 0)
    assert packets.ping(port, 6)[1] == scs.COMM_RX_TIMEOUT  # --silent 6
    assert packets.write1ByteTxRx(port, 2, TORQUE_ENABLE, 1)[0] == scs.COMM_SUCCESS
    port.closePort()
    process.stdin.write(b"status\n")
    process.stdin.flush()
    header = lines.next()
    assert "joint" in header and "present" in header and "offset" in header
    rows = [lines.next() for _ in IDS]
    assert rows[0].split()[:5] == ["1", "shoulder_pan", "off", "2358", "2358"]
    assert rows[1].split()[:3] == ["2", "shoulder_lift", "on"]
    assert rows[5].split()[-1] == "silent"
    process.stdin.write(b"jump 3\nmove 9 100\nmove 3 +100\n")
    process.stdin.flush()
    assert lines.next().startswith("unknown command 'jump'; commands: help, status")
    assert lines.next().startswith("no servo '9' on this bus")
    assert lines.next() == "servo 3 moved by hand from 2238 to 2338"
    process.stdin.write(b"quit\n")
    process.stdin.flush()
    assert process.wait(timeout=10) == 0
    assert process.stderr.read() == b""


def test_cli_sigterm_ends_it_cleanly(start_cli):
    process, lines, port_path = start_cli()
    # Held open here, the port's number cannot go to another pseudo-terminal (a parallel test's) meanwhile.
    held = os.open(port_path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=10) == 0
        assert process.stderr.read() == b""
        assert not os.path.exists(port_path)  # its end closed: the port is gone
    finally:
        os.close(held)


def test_cli_runs_on_after_end_of_input_until_sigterm(start_cli):
    process, lines, port_path = start_cli(stdin=subprocess.DEVNULL)
    lines.next()
    assert "keeps running" in lines.next()
    time.sleep(0.2)
    assert process.poll() is None
    port, packets = open_bus(port_path)
    assert packets.ping(port, 4) == (777, scs.COMM_SUCCESS, 0)
    port.closePort()
    process.send_signal(signal.SIGTERM)
    assert process.wait(timeout=10) == 0
    assert process.stderr.read() == b""


# -- the command line: a scripted hand (an emulated leader) ------------------------------------------------

ACCEPTED = (
    "help, status, sweep [SECONDS], move ID STEPS, figure8 [PERIOD_S], play FILE, hold, "
    "silent ID, corrupt ID, answer ID|all, mute, close, quit"
)
KEYFRAME_LINE = (
    "a keyframe is SECONDS then 6 angles in degrees "
    "(shoulder_pan shoulder_lift elbow_flex wrist_flex wrist_roll gripper)"
)

BAD_KEYFRAMES = "# a good keyframe, then one short of an angle\n1 0 0 0 0 0 0\n2 0 0 0 0 0\n"


def send(process, command: str) -> None:
    process.stdin.write(command.encode() + b"\n")
    process.stdin.flush()


@pytest.fixture(scope="module")
def cli_session(tmp_path_factory):
    """One `so101 fake-arm` (started in a folder holding bad.keyframes) for replies that change nothing."""
    folder = tmp_path_factory.mktemp("hand")
    (folder / "bad.keyframes").write_text(BAD_KEYFRAMES)
    process = subprocess.Popen(
        [str(SO101), "fake-arm"], stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=folder,
        env=dict(os.environ, SO101_LANG="en"),
    )
    lines = Lines(process.stdout)
    port_path = lines.next()
    lines.next()
    yield process, lines, port_path
    process.kill()
    process.wait(timeout=10)
    for stream in (process.stdin, process.stdout, process.stderr):
        stream.close()


@pytest.mark.parametrize("command, reply", [
    ("figure8 0", "figure8 takes a period in seconds, from 1 to 600; got '0'"),
    ("figure8 fast", "figure8 takes a period in seconds, from 1 to 600; got 'fast'"),
    ("figure8 8 2", f"usage: figure8 [PERIOD_S]; commands: {ACCEPTED}"),
    ("play", f"usage: play FILE; commands: {ACCEPTED}"),
    ("play nowhere.keyframes", "no keyframe file nowhere.keyframes"),
    ("play bad.keyframes", f"bad.keyframes, line 3: 6 values; {KEYFRAME_LINE}"),
    ("hold now", f"usage: hold; commands: {ACCEPTED}"),
    ("hold", "hand: no joint was moving by hand; they stand where they are"),
    ("wave", f"unknown command 'wave'; commands: {ACCEPTED}"),
])
def test_cli_a_hand_mistake_is_one_line_and_the_emulator_runs_on(cli_session, command, reply):
    process, lines, port_path = cli_session
    send(process, command)
    assert lines.next() == reply
    port, packets = open_bus(port_path)
    assert packets.ping(port, 1) == (777, scs.COMM_SUCCESS, 0)
    assert sync_read(port, packets, PRESENT_POSITION, 2)[1] == {i: MECHANICS[i].centre for i in IDS}  # nothing moved
    port.closePort()


def test_cli_plays_a_leader_figure_eight_and_keyframes_and_holds(start_cli):
    process, lines, port_path = start_cli("--hand", "figure8")
    lines.next()
    assert lines.next() == "hand: figure eight, 8 s a loop, joints 1-6 (hold stops it)"
    port, packets = open_bus(port_path)
    first = sync_read(port, packets, PRESENT_POSITION, 2)[1]
    time.sleep(0.4)  # easing in: shoulder_pan ≈ 0.35 x 30 sin(18°) ≈ 3°, 37 steps
    assert abs(sync_read(port, packets, PRESENT_POSITION, 2)[1][1] - first[1]) > 10
    send(process, "figure8 2")
    assert lines.next() == "hand: figure eight, 2 s a loop, joints 1-6 (hold stops it)"
    send(process, "hold")
    assert lines.next() == "hand: let go of joints 1-6 where they stand"
    held = sync_read(port, packets, PRESENT_POSITION, 2)[1]
    time.sleep(0.2)
    assert sync_read(port, packets, PRESENT_POSITION, 2)[1] == held
    # Servo 2 held by its motor where the hand left it, as a driver does it: goal = present, then torque on.
    assert packets.write2ByteTxRx(port, 2, GOAL_POSITION, held[2])[0] == scs.COMM_SUCCESS
    assert packets.write1ByteTxRx(port, 2, TORQUE_ENABLE, 1)[0] == scs.COMM_SUCCESS
    send(process, f"play {EXAMPLE_KEYFRAMES}")
    assert lines.next() == (
        f"hand: playing {EXAMPLE_KEYFRAMES} once, 8 keyframes over 6 s, joints 1, 3-6; torque holds 2 (hold stops it)"
    )
    time.sleep(0.5)  # half way to the first keyframe, elbow_flex -80° at 1 s
    moved = sync_read(port, packets, PRESENT_POSITION, 2)[1]
    assert moved[3] < held[3] - 100 and moved[2] == held[2]
    send(process, "hold")
    assert lines.next() == "hand: let go of joints 1, 3-6 where they stand"
    port.closePort()
    send(process, "quit")
    assert process.wait(timeout=10) == 0
    assert process.stderr.read() == b""


def test_cli_a_bad_hand_file_stops_the_start_in_one_line(tmp_path):
    (tmp_path / "bad.keyframes").write_text(BAD_KEYFRAMES)
    result = subprocess.run(
        [str(SO101), "fake-arm", "--hand", "bad.keyframes"], capture_output=True, text=True, cwd=tmp_path, timeout=30,
    )
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.splitlines()[-1] == (
        f"so101 fake-arm: error: argument --hand: bad.keyframes, line 3: 6 values; {KEYFRAME_LINE} "
        "(--hand takes figure8 or a keyframe file)"
    )
