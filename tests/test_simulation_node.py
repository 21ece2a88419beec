"""The body nodes' event loop, driven by dora.testing.MockNode (no daemon).

The contract tests take the `body` fixture and run on every body in so101.bodies.registry
(PyBullet's node, MuJoCo's, and the real arm's on `so101 fake-arm`'s emulated bus); the
`simulated_body` ones on the simulations only (a model file, a camera); the rest are
PyBullet's own (the course's motion, servo mode).
"""

from __future__ import annotations

import datetime
import math
import re

import pyarrow as pa
import pytest

from so101.bodies.registry import BODIES, SIMULATED_BODIES
from so101.runtime.dataflow import MAX_STEPS_PER_TICK, TickClock
from tests.helpers.dataflow import TICK, TICK_TIMER_CONFIG, body_environment, run_simulation_node

pytestmark = pytest.mark.slow  # drives every body's node for seconds of simulated time: not in the fast subset


@pytest.fixture(params=list(BODIES))
def body(request, monkeypatch, tmp_path) -> str:
    with body_environment(request.param, tmp_path) as (env, _):
        for name, value in env.items():
            monkeypatch.setenv(name, value)
        yield request.param


@pytest.fixture(params=SIMULATED_BODIES)
def simulated_body(request) -> str:
    return request.param


def ticks(count):
    return [TICK] * count


def last_state(node, output="joint_state"):
    return node.outputs[output][-1].to_pylist()


def missed_reads(log: str) -> int:
    """Ticks whose read of the emulated arm (a thread of this busy process) failed, as the real arm's node
    logs them: those publish nothing, by design. 0 for a simulation."""
    return sum(int(count) for count in re.findall(r"answer again after (\d+) failed read", log))


def test_each_tick_publishes_five_arm_angles_and_the_gripper(monkeypatch, capsys, body):
    code, node = run_simulation_node(monkeypatch, ticks(25), body=body)
    assert code == 0
    missed = missed_reads(capsys.readouterr().out)
    assert len(node.outputs["joint_state"]) + missed == 25
    assert len(node.outputs["gripper_state"]) + missed == 25
    state = node.outputs["joint_state"][-1]
    assert state.type == pa.float64() and len(state) == 5
    assert len(node.outputs["gripper_state"][-1]) == 1
    # At home and holding still: every angle within 2.5° of zero (MuJoCo's soft servos let
    # shoulder_lift sag about 2° under gravity; PyBullet's hold within 0.1°).
    assert all(abs(angle) < 2.5 for angle in state.to_pylist())


def test_the_loaded_line_says_how_the_body_runs(monkeypatch, capsys, body):
    # Tools wait for this line (so101.runtime.dataflow.LOADED_MARKS); a simulation names its display
    # mode, the real arm says REAL.
    run_simulation_node(monkeypatch, ticks(1), body=body)
    loaded = [line for line in capsys.readouterr().out.splitlines() if "SO-101 loaded, " in line]
    assert len(loaded) == 1
    assert f"({'REAL' if body == 'real' else 'DIRECT'} mode, step 4 ms, " in loaded[0]


@pytest.mark.parametrize(
    "command",
    [pa.array([0, 45]), pa.array([0, 45], type=pa.int8()), pa.array([0.0, 45.0], type=pa.float32())],
    ids=["int64", "int8", "float32"],
)
def test_single_joint_command_is_reached(monkeypatch, command, body):
    code, node = run_simulation_node(monkeypatch, [("joint_cmd", command)] + ticks(300), body=body)
    assert code == 0
    assert math.isclose(last_state(node)[0], 45.0, abs_tol=1.0)  # shoulder_pan: no load from gravity


def test_course_batch_is_reached(monkeypatch, capsys):
    batch = [-30.0, 45.0, -60.0, 30.0, 0.0]
    code, node = run_simulation_node(monkeypatch, [("joint_cmd", pa.array(batch, type=pa.float32()))] + ticks(400))
    assert code == 0
    for reached, target in zip(last_state(node), batch):
        assert math.isclose(reached, target, abs_tol=1.0)
    assert "all joint targets -> [-30.0, 45.0, -60.0, 30.0, 0.0]°" in capsys.readouterr().out


BAD_COMMANDS = {
    "empty": pa.array([], type=pa.float64()),
    "three values": pa.array([1.0, 2.0, 3.0]),
    "nan batch": pa.array([float("nan")] * 5),
    "inf single": pa.array([0.0, float("inf")]),
    "nulls": pa.array([0.0, None]),
    "strings": pa.array(["0", "90"]),
    "booleans": pa.array([True, False]),
    "nested": pa.array([[0.0, 90.0]]),
    "struct": pa.array([{"joint": 0, "angle": 90.0}]),
    "index 9": pa.array([9, 10]),
    "index -1": pa.array([-1, 10]),
    "index 1.5": pa.array([1.5, 10.0]),
}


@pytest.mark.parametrize("bad", list(BAD_COMMANDS.values()), ids=list(BAD_COMMANDS))
def test_bad_joint_cmd_is_logged_and_targets_stay(monkeypatch, capsys, bad, body):
    events = [("joint_cmd", pa.array([0, 30]))] + ticks(200) + [("joint_cmd", bad)] + ticks(100)
    code, node = run_simulation_node(monkeypatch, events, body=body)
    assert code == 0
    log = capsys.readouterr().out
    assert len(node.outputs["joint_state"]) + missed_reads(log) == 300  # kept stepping
    state = last_state(node)
    assert all(math.isfinite(angle) for angle in state)
    assert math.isclose(state[0], 30.0, abs_tol=1.0)  # the previous target still holds
    rejected = [line for line in log.splitlines() if "ignored invalid joint_cmd" in line]
    assert len(rejected) == 1
    assert f"array of length {len(bad)}" in rejected[0]  # what arrived
    assert "; accepted: a numeric array in degrees, [joint_idx, angle]" in rejected[0]


def test_angle_beyond_limit_is_clamped_and_logged(monkeypatch, capsys, body):
    code, node = run_simulation_node(monkeypatch, [("joint_cmd", pa.array([0, 500]))] + ticks(400), body=body)
    assert code == 0
    assert math.isclose(last_state(node)[0], 110.0, abs_tol=1.0)  # shoulder_pan's URDF limit
    assert "shoulder_pan 500° is beyond its limits [-110.0°, 110.0°]: clamped to 110.0°" in capsys.readouterr().out


def test_gripper_single_and_six_value_batch(monkeypatch, body):
    code, node = run_simulation_node(monkeypatch, [("joint_cmd", pa.array([5, 30]))] + ticks(200), body=body)
    assert math.isclose(last_state(node, "gripper_state")[0], 30.0, abs_tol=1.0)
    code, node = run_simulation_node(monkeypatch, [("joint_cmd", pa.array([10, 0, 0, 0, 0, 60]))] + ticks(250), body=body)
    assert math.isclose(last_state(node)[0], 10.0, abs_tol=1.0)
    assert math.isclose(last_state(node, "gripper_state")[0], 60.0, abs_tol=1.0)


@pytest.mark.parametrize("period_ms", [4, 10])
def test_physics_step_follows_the_tick_period(monkeypatch, capsys, make_sim, period_ms):
    config = {"inputs": {"tick": f"dora/timer/millis/{period_ms}"}}
    code, node = run_simulation_node(monkeypatch, [("joint_cmd", pa.array([0, 90]))] + ticks(20), node_config=config)
    assert code == 0
    assert f"step {period_ms} ms" in capsys.readouterr().out
    # The same 20 steps of a simulator built with that step give the same angle (PyBullet is
    # deterministic); at the course's 3 rad/s from the first step, 20 ticks of 4 ms and of 10 ms
    # end 0.24 rad (13.75°) and 0.6 rad (34.4°) along the way to 90°.
    reference = make_sim(time_step_s=period_ms / 1000)
    reference.set_targets_deg([90, 0, 0, 0, 0, 0])
    reference.step(20)
    assert last_state(node)[0] == pytest.approx(reference.joint_angles_deg()[0], abs=1e-6)
    assert last_state(node)[0] == pytest.approx(13.75 if period_ms == 4 else 34.4, abs=0.5)


def test_a_tick_that_is_not_a_timer_gets_the_courses_4_ms(monkeypatch, capsys, body):
    run_simulation_node(monkeypatch, ticks(1), node_config={"inputs": {"tick": "other/output"}}, body=body)
    assert "tick is not a dora timer; physics step set to 4 ms" in capsys.readouterr().out


def test_unknown_events_are_ignored(monkeypatch, body):
    events = [{"type": "INPUT_CLOSED", "id": "joint_cmd"}, {"type": "ERROR", "error": "x"}, ("other", pa.array([1]))]
    code, node = run_simulation_node(monkeypatch, events + ticks(3), body=body)
    assert code == 0 and len(node.outputs["joint_state"]) == 3


def test_bad_environment_value_gives_one_line_and_exit_2(monkeypatch, capsys, body):
    code, _ = run_simulation_node(monkeypatch, ticks(1), body=body, SO101_IMAGE_HZ="fast")
    assert code == 2
    assert "SO101_IMAGE_HZ='fast' is not a number >= 0" in capsys.readouterr().err


def test_a_bad_language_gives_one_line_and_exit_2(monkeypatch, capsys, body):
    # so101.lang's one rule: anything but zh or en is refused, not taken for zh.
    code, node = run_simulation_node(monkeypatch, ticks(1), body=body, SO101_LANG="english")
    err = capsys.readouterr().err
    assert code == 2 and "joint_state" not in node.outputs
    assert err.count("\n") == 1 and "cannot start: unknown language 'english'" in err and "use zh or en" in err


def test_servo_mode_is_chosen_by_the_environment_and_low_damping_overshoots(monkeypatch, capsys):
    step = [("joint_cmd", pa.array([0, 90]))] + ticks(200)
    _, servo = run_simulation_node(monkeypatch, step, SO101_CONTROL="servo", SO101_SERVO_ZETA="0.2")
    assert "servo control" in capsys.readouterr().out
    peak_deg = max(state.to_pylist()[0] for state in servo.outputs["joint_state"])
    assert peak_deg > 100.0  # about 23% over 90°
    _, position = run_simulation_node(monkeypatch, step, SO101_CONTROL="position")
    assert max(state.to_pylist()[0] for state in position.outputs["joint_state"]) < 90.5


def test_unknown_control_mode_gives_one_line_and_exit_2(monkeypatch, capsys):
    code, _ = run_simulation_node(monkeypatch, ticks(1), SO101_CONTROL="torque")
    assert code == 2
    assert "unknown control mode 'torque'; use one of: position, servo" in capsys.readouterr().err


@pytest.mark.parametrize("ending", ["STOP", "Ctrl-C"])
def test_stop_and_ctrl_c_close_the_body_and_exit_0(monkeypatch, ending, body):
    from dora.testing import MockNode

    body_class = BODIES[body].body_class()
    closed = []
    close = body_class.close
    # What is closed: PyBullet's client id (it is gone after close), or the MuJoCo body itself.
    monkeypatch.setattr(body_class, "close", lambda self: (closed.append(getattr(self, "client", self)), close(self)))
    if ending == "Ctrl-C":
        next_event = MockNode.__next__

        def interrupted_after_five_ticks(self):
            if len(self.outputs.get("joint_state", [])) == 5:
                raise KeyboardInterrupt
            return next_event(self)

        monkeypatch.setattr(MockNode, "__next__", interrupted_after_five_ticks)
    code, node = run_simulation_node(monkeypatch, ticks(10), body=body)
    assert code == 0
    assert len(node.outputs["joint_state"]) == (5 if ending == "Ctrl-C" else 10)
    assert len(closed) == 1
    if body == "pybullet":
        import pybullet as p

        assert not p.isConnected(physicsClientId=closed[0])


def test_missing_model_gives_one_line_and_exit_2(monkeypatch, capsys, tmp_path, simulated_body):
    code, _ = run_simulation_node(monkeypatch, ticks(1), body=simulated_body, SO101_ASSETS_DIR=str(tmp_path))
    assert code == 2
    err = capsys.readouterr().err
    assert "model file missing" in err and "so101 assets" in err


def test_image_output_shows_the_arm_at_the_asked_rate(monkeypatch, simulated_body):
    body = simulated_body
    import numpy as np
    from dora.testing import MockNode

    from tests.helpers.images import arm_pixels

    metadata_sent = []
    send_output = MockNode.send_output

    def send_and_keep_metadata(self, output_id, data, metadata=None):
        if output_id == "image":
            metadata_sent.append(metadata)
        send_output(self, output_id, data, metadata)

    monkeypatch.setattr(MockNode, "send_output", send_and_keep_metadata)
    # 25 Hz on a 4 ms tick: one image every 10 ticks.
    code, node = run_simulation_node(monkeypatch, ticks(30), body=body, SO101_IMAGE_HZ="25")
    assert code == 0
    assert len(node.outputs["image"]) == 3
    assert metadata_sent[-1] == {"width": 320, "height": 240, "encoding": "rgb8"}
    image = node.outputs["image"][-1]
    assert image.type == pa.uint8()
    rgb = np.asarray(image.to_numpy()).reshape(240, 320, 3)
    assert arm_pixels(rgb).sum() > 0.02 * 320 * 240


def test_fast_mode_keeps_the_image_rate_in_simulated_time(monkeypatch):
    # 30 ticks of 7 steps are 210 steps of 4 ms; at 25 Hz an image is due every 10 steps.
    code, node = run_simulation_node(monkeypatch, ticks(30), SO101_FAST_STEPS="7", SO101_IMAGE_HZ="25")
    assert code == 0
    assert 19 <= len(node.outputs["image"]) <= 21


def test_no_image_output_by_default(monkeypatch, body):
    code, node = run_simulation_node(monkeypatch, ticks(30), body=body)
    assert code == 0
    assert "image" not in node.outputs


def test_a_tick_after_dropped_ones_takes_their_steps_too(monkeypatch):
    # Timer stamps 4 ms apart, then 12 ms (two ticks dropped by a late node), then 1 s (a stall).
    start = datetime.datetime(2026, 1, 1, tzinfo=datetime.timezone.utc)
    stamps_ms = [0, 4, 8, 20, 1020]
    events = [("joint_cmd", pa.array([0, 90]))] + [
        {"type": "INPUT", "id": "tick", "value": pa.array([], type=pa.null()),
         "metadata": {"timestamp": start + datetime.timedelta(milliseconds=ms)}}
        for ms in stamps_ms
    ]
    code, node = run_simulation_node(monkeypatch, events)
    assert code == 0
    # 1 + 1 + 1 + 3 + 10 (a stall is let go past MAX_STEPS_PER_TICK) steps at 3 rad/s = 0.012 rad/step
    assert MAX_STEPS_PER_TICK == 10
    assert last_state(node)[0] == pytest.approx(math.degrees(16 * 0.012), abs=0.01)


def test_the_tick_clock_counts_from_the_first_tick_so_timer_jitter_adds_no_steps():
    start = datetime.datetime(2026, 1, 1, tzinfo=datetime.timezone.utc)
    clock = TickClock(0.004)
    # The tick due at 8 ms is dropped and the next one fires late (10.1 ms), then on time;
    # the one at 20 ms is dropped too. Tick to tick, rounding each gap would owe
    # 1, 1, 2, 1 (a 1.9 ms gap still steps once), 1, 2: 8 steps for 7 timer periods.
    owed = [clock.steps_due(start + datetime.timedelta(milliseconds=ms)) for ms in (0, 4, 10.1, 12, 16, 24)]
    assert owed == [1, 1, 2, 1, 1, 1]
    assert sum(owed) == 24 / 4 + 1  # the timer's own count: one step per period, and the first tick's
    assert TickClock(0.004).steps_due(None) == 1


def test_mujoco_without_an_opengl_back_end_says_which_packages_in_one_line(monkeypatch, capsys):
    import mujoco

    def no_egl(*args, **kwargs):
        raise RuntimeError("Cannot initialize a EGL device display.")

    monkeypatch.setattr(mujoco, "Renderer", no_egl)
    code, _ = run_simulation_node(monkeypatch, ticks(1), body="mujoco", SO101_IMAGE_HZ="10")
    assert code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "MuJoCo cannot draw offscreen (RuntimeError: Cannot initialize a EGL device display.)" in err
    assert "apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri" in err


TASK_CONFIG = {**TICK_TIMER_CONFIG, "outputs": ["joint_state", "gripper_state", "object_state", "task_status"]}


def test_a_task_publishes_its_objects_each_tick_and_success_when_it_changes_and_resets_on_command(
        monkeypatch, capsys, simulated_body):
    from dora.testing import MockNode

    from so101.tasks import CUBE_TO_BOX

    metadata_sent = {"object_state": [], "task_status": []}
    send_output = MockNode.send_output

    def send_and_keep_metadata(self, output_id, data, metadata=None):
        if output_id in metadata_sent:
            metadata_sent[output_id].append(metadata)
        send_output(self, output_id, data, metadata)

    monkeypatch.setattr(MockNode, "send_output", send_and_keep_metadata)
    reset = {"type": "INPUT", "id": "task_cmd", "value": pa.array(["reset"]), "metadata": {"request": "1"}}
    reset_to_40 = {"type": "INPUT", "id": "task_cmd", "value": pa.array(["reset 40"]), "metadata": {"request": "2"}}
    bad = {"type": "INPUT", "id": "task_cmd", "value": pa.array(["reset x"]), "metadata": {}}
    events = ticks(5) + [reset] + ticks(5) + [bad, reset_to_40] + ticks(5)
    code, node = run_simulation_node(monkeypatch, events, node_config=TASK_CONFIG, body=simulated_body,
                                     SO101_TASK="cube_to_box", SO101_SEED="7")
    assert code == 0
    assert len(node.outputs["object_state"]) == 15
    assert all(meta == {"names": ",".join(CUBE_TO_BOX.object_state_names)} for meta in metadata_sent["object_state"])
    first, after_reset, after_seed = (node.outputs["object_state"][index].to_pylist() for index in (0, 5, 10))
    assert first[0:3] == pytest.approx(CUBE_TO_BOX.layout(7).cube_xyz_m, abs=1e-3)
    assert after_reset[0:3] == pytest.approx(CUBE_TO_BOX.layout(8).cube_xyz_m, abs=1e-3)  # `reset`: the next seed
    assert after_seed[0:3] == pytest.approx(CUBE_TO_BOX.layout(40).cube_xyz_m, abs=1e-3)
    assert node.outputs["object_state"][0].type == pa.float32()
    # Success at the first tick, then after each reset (the answer to it), and only then: nothing fell in.
    assert [status.to_pylist() for status in node.outputs["task_status"]] == [[False]] * 3
    assert metadata_sent["task_status"] == [
        {"task": "cube_to_box", "seed": 7, "reply_to": ""},
        {"task": "cube_to_box", "seed": 8, "reply_to": "1"},
        {"task": "cube_to_box", "seed": 40, "reply_to": "2"},
    ]
    log = capsys.readouterr().out
    assert "task cube_to_box: laid out from seed 8, the arm at home" in log
    assert "ignored invalid task_cmd: a seed is a whole number >= 0, got 'x'" in log


def test_without_a_task_a_body_publishes_no_objects_and_ignores_task_cmd(monkeypatch, capsys, simulated_body):
    reset = {"type": "INPUT", "id": "task_cmd", "value": pa.array(["reset"]), "metadata": {}}
    code, node = run_simulation_node(monkeypatch, ticks(3) + [reset] + ticks(2), node_config=TASK_CONFIG,
                                     body=simulated_body)
    assert code == 0
    assert "object_state" not in node.outputs and "task_status" not in node.outputs
    assert len(node.outputs["joint_state"]) == 5
    assert "ignored invalid task_cmd: this body runs no task" in capsys.readouterr().out
