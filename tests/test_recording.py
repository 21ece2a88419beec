"""The recorder's logic without dora (so101/dataset/recording.py), the prompt's side of it, replay's
maths (so101/dataset/replay.py), the gripper's mapping, and the dataflows `--record` and
`so101 replay` run."""

from __future__ import annotations

import threading
from types import SimpleNamespace

import numpy as np
import pyarrow as pa
import pytest

from so101.dataset.features import (
    ACTION_KEY, ENVIRONMENT_KEY, IMAGE_KEY, MOTOR_NAMES, REWARD_KEY, STATE_KEY, SUCCESS_KEY, WRIST_IMAGE_KEY, from_lerobot,
    to_lerobot,
)
from so101.dataset.messages import (RecordCommand, decode_record_cmd, encode_record_cmd, recording_from_metadata,
                                    recording_metadata)
from so101.dataset.recording import FrameClock, Recording
from so101.dataset.replay import ramp_deg, send_time_s, tracking_errors_deg, tracking_line
from so101.prompt.commands import Episodes, ParseError, parse_command
from so101.prompt.recorder_link import RecorderLink
from so101.observe import ALL_OBSERVED, parse_observed
from so101.runtime.dataflow import (
    DATAFLOW_FILE, dataflow_copy, with_camera, with_policy, with_recorder, with_replay, with_task, with_web_view,
)
from tests.helpers.dataflow import TICK, TICK_TIMER_CONFIG, run_simulation_node


# -- the gripper in LeRobot's 0-100 ---------------------------------------------------------------

@pytest.mark.parametrize("gripper_deg, lerobot", [(-10.0, 0.0), (100.0, 100.0), (45.0, 50.0), (0.0, 100 / 11)])
def test_the_gripper_maps_the_urdf_range_onto_lerobots(gripper_deg, lerobot):
    values = to_lerobot([1.0, -2.0, 3.5, 4.0, -5.0, gripper_deg])
    assert values.dtype == np.float32
    assert values[:5].tolist() == [1.0, -2.0, 3.5, 4.0, -5.0]  # arm joints: degrees in both
    assert values[5] == pytest.approx(lerobot, abs=1e-4)
    assert from_lerobot(values)[5] == pytest.approx(gripper_deg, abs=1e-4)


def test_motor_names_are_so101_followers():
    assert MOTOR_NAMES == ("shoulder_pan.pos", "shoulder_lift.pos", "elbow_flex.pos", "wrist_flex.pos",
                           "wrist_roll.pos", "gripper.pos")


def test_from_lerobot_takes_a_whole_episode():
    frames = np.array([to_lerobot([0, 0, 0, 0, 0, g]) for g in (-10, 45, 100)])
    assert from_lerobot(frames)[:, 5] == pytest.approx([-10, 45, 100], abs=1e-4)


# -- the frame clock --------------------------------------------------------------------------------

def test_frames_come_at_the_rate_counted_from_the_first():
    clock = FrameClock(30, start_s=100.0)
    due = [clock.due(100.0 + k * 0.005) for k in range(200)]  # 1 s of 5 ms ticks
    assert sum(due) == 30 and due[0] == 1 and max(due) == 1


def test_a_late_tick_adds_the_frames_it_owes_and_a_stall_starts_afresh():
    clock = FrameClock(10, start_s=0.0)
    assert clock.due(0.0) == 1
    assert clock.due(0.35) == 3  # frames 1, 2 and 3 were due
    assert clock.due(100.0) == 1  # a stall: one frame, no flood
    assert clock.due(100.1) == 1


# -- the recorder's commands ------------------------------------------------------------------------

class FakeEpisode:
    def __init__(self, task, writer, fail=None):
        self.task, self.writer, self.fail = task, writer, fail
        self.rows: list[tuple] = []
        self.discarded = False
        self.release = threading.Event()
        self.release.set()

    @property
    def frames(self):
        return len(self.rows)

    def add_frame(self, frame):
        self.rows.append((frame[STATE_KEY].copy(), frame[ACTION_KEY].copy(), frame.get(IMAGE_KEY)))
        self.frames_given = getattr(self, "frames_given", []) + [frame]

    def save(self):
        self.release.wait(5)
        if self.fail:
            raise self.fail
        self.writer.saved.append(self)
        self.writer.episodes.append(SimpleNamespace(index=len(self.writer.episodes), length=self.frames,
                                                    tasks=(self.task,), duration_s=self.frames / 30))

    def discard(self):
        self.discarded = True


class FakeWriter:
    def __init__(self):
        self.saved: list[FakeEpisode] = []
        self.episodes: list = []
        self.fail = None

    def start_episode(self, task):
        return FakeEpisode(task, self, self.fail)


class Clock:
    def __init__(self):
        self.now_s = 0.0

    def __call__(self):
        return self.now_s


def recording(needs_image=False, lang="en", task=None, observed=ALL_OBSERVED):
    said: list[str] = []
    clock = Clock()
    writer = FakeWriter()
    return (Recording(writer, "/data/set", 30, lang, needs_image, said.append, clock, task, observed=observed), writer,
            clock, said)


def feed(rec, clock, seconds, arm=(10.0, 20.0, 30.0, 40.0, 50.0), gripper=45.0):
    rec.on_joint_state(arm)
    rec.on_gripper_state([gripper])
    for _ in range(round(seconds / 0.005)):
        clock.now_s += 0.005
        rec.tick()


def record_for(rec, clock, task, seconds):
    """An episode of `task` started once the arm's state has come, and `seconds` of it recorded."""
    feed(rec, clock, 0.01)
    rec.command(RecordCommand("record", task))
    feed(rec, clock, seconds)


@pytest.mark.parametrize("stamped", [True, False])
def test_a_recorder_that_stalls_keeps_each_picture_on_its_frame(stamped):
    """A camera's pictures at 30 a second, numbered; the recorder, stalled for 0.4 s, reads its queue at once
    afterwards. With the times dora stamps on the ticks and pictures, each frame holds the picture of its
    moment: in order, none twice, none skipped. Without them, the frames of the stall repeat one picture and
    those sent during it are lost: the failure the stamps mend."""
    rec, _, clock, _ = recording(needs_image=True)
    rec.on_joint_state([0.0] * 5)
    rec.on_gripper_state([0.0])
    rec.command(RecordCommand("record", "watch"))
    # What was sent, in time order: a picture every 1/30 s (3 ms after a frame is due), a tick every 5 ms.
    events = sorted([(0.003 + n / 30, "image", n) for n in range(45)] + [(k * 0.005, "tick", None) for k in range(300)])
    for sent_s, kind, number in events:
        clock.now_s = 0.9 if 0.5 <= sent_s <= 0.9 else sent_s  # stalled from 0.5 s to 0.9 s: all read at 0.9 s
        stamp = sent_s if stamped else None
        if kind == "image":
            rec.on_image(np.full((2, 2, 3), number, np.uint8), sent_s=stamp)
        else:
            rec.tick(stamp)
    numbers = [int(row[2][0, 0, 0]) for row in rec.episode.rows]
    steps = np.diff(numbers)
    if stamped:
        assert numbers[:3] == [0, 1, 2] and set(steps) == {1}, numbers
    else:
        assert steps.min() == 0 and steps.max() > 2, numbers


def test_an_episode_samples_state_and_target_at_each_frame():
    rec, writer, clock, said = recording()
    rec.on_joint_state([10, 20, 30, 40, 50])
    rec.on_gripper_state([45.0])
    rec.on_joint_target([11, 21, 31, 41, 51, 100.0])
    assert rec.command(RecordCommand("record", "pick the cube")) == [
        "● recording episode 0: task 'pick the cube' (stop: stop, drop: discard)"]
    feed(rec, clock, 1.0)
    episode = rec.episode
    assert 30 <= episode.frames <= 31
    state, action, image = episode.rows[0]
    assert state.tolist() == pytest.approx([10, 20, 30, 40, 50, 50.0])  # gripper 45° -> 50
    assert action.tolist() == pytest.approx([11, 21, 31, 41, 51, 100.0])
    assert image is None
    reply = rec.command(RecordCommand("stop"))
    assert reply[0].startswith(f"■ episode 0: {episode.frames} frames (") and reply[0].endswith("saving...")
    rec.close()
    assert writer.saved == [episode] and episode.task == "pick the cube"
    assert said[-1].startswith(f"✓ episode 0 saved: {episode.frames} frames")


def test_without_a_target_the_action_is_where_the_arm_stands():
    rec, writer, clock, said = recording()
    rec.on_joint_state([1, 2, 3, 4, 5])
    rec.on_gripper_state([-10.0])
    rec.command(RecordCommand("record", "t"))
    feed(rec, clock, 0.1, arm=(1, 2, 3, 4, 5), gripper=-10.0)
    state, action, _ = rec.episode.rows[0]
    assert action.tolist() == state.tolist() == pytest.approx([1, 2, 3, 4, 5, 0.0])


def test_with_video_frames_wait_for_the_first_picture():
    rec, writer, clock, said = recording(needs_image=True)
    rec.on_joint_state([0] * 5)
    rec.on_gripper_state([0.0])
    assert rec.command(RecordCommand("record", "t"))[0].endswith("(waiting for the first picture; frames count from then)")
    feed(rec, clock, 0.5, arm=(0,) * 5, gripper=0.0)
    assert rec.episode.frames == 0
    picture = np.zeros((240, 320, 3), np.uint8)
    rec.on_image(picture)
    feed(rec, clock, 0.5, arm=(0,) * 5, gripper=0.0)
    assert 15 <= rec.episode.frames <= 16 and rec.episode.rows[0][2] is picture


@pytest.mark.parametrize("observe, keys", [
    ("state,environment,front,wrist", [ENVIRONMENT_KEY, IMAGE_KEY, WRIST_IMAGE_KEY]),
    ("state,front,wrist", [IMAGE_KEY, WRIST_IMAGE_KEY]),  # a policy trained on it sees
    ("state,environment,front", [ENVIRONMENT_KEY, IMAGE_KEY]),
])
def test_a_tasks_frames_hold_what_they_observe_and_wait_only_for_that(observe, keys):
    from so101.tasks import CUBE_TO_BOX

    rec, writer, clock, said = recording(needs_image=True, task=CUBE_TO_BOX, observed=parse_observed(observe))
    rec.on_object_state([0.0] * len(CUBE_TO_BOX.object_state_names))
    rec.on_image(np.zeros((240, 320, 3), np.uint8))
    record_for(rec, clock, "put the cube in the box", 0.5)
    if WRIST_IMAGE_KEY in keys:  # a frame waits for every picture it holds
        assert rec.episode.frames == 0
        rec.on_wrist_image(np.ones((240, 320, 3), np.uint8))
        feed(rec, clock, 0.5)
    assert 15 <= rec.episode.frames <= 16
    given = rec.episode.frames_given[0]
    assert {key for key in given if key.startswith("observation.") and key != STATE_KEY} == set(keys)
    assert {REWARD_KEY, SUCCESS_KEY} <= set(given)  # not observations: they stay


@pytest.mark.parametrize("lang", ["en", "zh"])
def test_refusals_are_one_line_and_change_nothing(lang):
    rec, writer, clock, said = recording(lang=lang)
    for command in (RecordCommand("stop"), RecordCommand("discard"), RecordCommand("record", "t"),
                    RecordCommand("record", ""), RecordCommand("jump"), decode_record_cmd("{not json")):
        reply = rec.command(command)
        assert len(reply) == 1 and "\n" not in reply[0]
    assert rec.episode is None and writer.saved == []
    rec.on_joint_state([0] * 5)
    rec.on_gripper_state([0.0])
    rec.command(RecordCommand("record", "t"))
    assert len(rec.command(RecordCommand("record", "again"))) == 1 and rec.episode.task == "t"


def test_discard_drops_the_episode_and_keeps_its_index():
    rec, writer, clock, said = recording()
    record_for(rec, clock, "t", 0.3)
    first = rec.episode
    assert rec.command(RecordCommand("discard"))[0].startswith("episode 0 discarded (")
    assert first.discarded and rec.episode is None
    assert rec.command(RecordCommand("record", "u"))[0].startswith("● recording episode 0:")


def test_toggle_starts_with_the_last_task_and_stops():
    rec, writer, clock, said = recording()
    feed(rec, clock, 0.01)
    assert rec.command(RecordCommand("toggle"))[0].startswith("record needs a task text")
    rec.command(RecordCommand("record", "wave"))
    feed(rec, clock, 0.2)
    assert "saving" in rec.command(RecordCommand("toggle"))[0]
    assert rec.command(RecordCommand("toggle"))[0] == "● recording episode 1: task 'wave' (stop: stop, drop: discard)"
    rec.close()


def test_a_failed_save_gives_its_index_back():
    rec, writer, clock, said = recording()
    writer.fail = OSError(28, "No space left on device")
    record_for(rec, clock, "t", 0.2)
    rec.command(RecordCommand("stop"))
    rec.close()
    writer.fail = None
    assert rec.command(RecordCommand("record", "u"))[0].startswith("● recording episode 0:")
    feed(rec, clock, 0.2)
    rec.command(RecordCommand("stop"))
    rec.close()
    listing = rec.command(RecordCommand("episodes"))
    assert listing[0] == "/data/set: 1 episodes, 30 fps" and listing[1].startswith("    0: ") and listing[1].endswith("  u")


def test_commands_are_answered_while_an_episode_saves_and_a_failed_save_says_why():
    rec, writer, clock, said = recording()
    writer.fail = OSError(28, "No space left on device")
    record_for(rec, clock, "t", 0.2)
    episode = rec.episode
    episode.release.clear()  # the save blocks until released
    rec.command(RecordCommand("stop"))
    assert rec.command(RecordCommand("episodes")) == ["/data/set: no episodes yet", "  (saving: 0)"]
    episode.release.set()
    rec.close()
    assert said[-1] == "✗ episode 0 not saved: [Errno 28] No space left on device"


def test_stop_saves_an_episode_still_recording():
    rec, writer, clock, said = recording()
    record_for(rec, clock, "t", 0.2)
    rec.close()
    assert len(writer.saved) == 1 and said[0] == "the dataflow stops: saving the unfinished episode 0"


def test_the_status_metadata_says_which_episode_records():
    rec, writer, clock, said = recording()
    assert recording_from_metadata(recording_metadata(rec.recording_now())) is None
    record_for(rec, clock, "put 方块 in", 0.2)
    assert recording_from_metadata(recording_metadata(rec.recording_now())) == (0, "put 方块 in")
    rec.command(RecordCommand("stop"))
    assert rec.recording_now() is None
    rec.command(RecordCommand("record", "wave"))
    assert rec.recording_now() == (1, "wave")
    rec.command(RecordCommand("discard"))
    assert rec.recording_now() is None
    rec.close()
    # A status from a recorder that does not say (or says nonsense): no marker.
    assert recording_from_metadata({"reply_to": "3"}) is None
    assert recording_from_metadata({"recording_episode": "x"}) is None


def test_record_cmd_text_round_trips():
    assert decode_record_cmd(encode_record_cmd("record", "put 方块 in")) == RecordCommand("record", "put 方块 in")
    assert isinstance(decode_record_cmd('{"task": 1}'), str)


# -- the prompt's side --------------------------------------------------------------------------------

@pytest.mark.parametrize("line, command", [
    ("record put the cube, in the box", Episodes("record", "put the cube, in the box")),
    ("RECORD   wave  twice", Episodes("record", "wave twice")),
    ("stop", Episodes("stop")), ("discard", Episodes("discard")), ("episodes", Episodes("episodes")),
])
def test_the_prompt_reads_the_recorder_commands(line, command):
    assert parse_command(line, "en") == command


@pytest.mark.parametrize("line", ["record", "stop now", "episodes 3"])
def test_malformed_recorder_commands_say_the_form(line):
    assert isinstance(parse_command(line, "en"), ParseError)


def test_the_link_matches_answers_and_shows_news():
    sent: list[tuple[str, str]] = []
    shown: list[str] = []
    link = RecorderLink(lambda text, request: sent.append((text, request)), shown.append)

    def answer():
        while not sent:
            pass
        link.on_status("news first", "")
        link.on_status("line one\nline two", sent[0][1])

    threading.Thread(target=answer).start()
    assert link.ask("episodes") == ["line one", "line two"]
    assert shown == ["  news first"]
    assert decode_record_cmd(sent[0][0]) == RecordCommand("episodes")
    assert link.ask("stop", timeout_s=0.05) is None
    # The recorder answers after all (a loaded machine): the answer is shown, not dropped.
    link.on_status("■ episode 0: 90 frames (3.0 s), saving...", sent[1][1])
    assert shown == ["  news first", "  ■ episode 0: 90 frames (3.0 s), saving..."]


def test_without_a_recorder_the_prompt_says_how_to_get_one(tmp_path):
    from so101.prompt.control import KeyboardControl
    from so101.prompt.poses import PoseStore

    control = KeyboardControl(lambda angles: None, PoseStore(tmp_path / "poses.json"), "en")
    assert control.handle_line("record x") == (["  recording is off: start with so101 teleop --record DIR"], False)


# -- replay's maths ---------------------------------------------------------------------------------

def test_the_ramp_keeps_every_joint_under_the_speed_and_ends_on_the_goal():
    start, goal = [0, 0, 0, 0, 0, 0], [90, -30, 10, 0, 5, 50]
    waypoints = ramp_deg(start, goal, fps=30, speed_deg_s=30)
    steps = np.abs(np.diff(np.vstack([start, waypoints]), axis=0))
    assert steps.max() <= 30 / 30 + 1e-9
    assert waypoints[-1].tolist() == goal and len(waypoints) == 90
    assert len(ramp_deg(goal, goal, fps=30)) == 1


def test_a_late_frame_pushes_the_next_ones_back_instead_of_bunching_them():
    assert send_time_s(10.0, 3, 0.1, 10.2) == pytest.approx(10.3)  # on time: the schedule
    assert send_time_s(10.0, 3, 0.1, 10.5) == pytest.approx(10.6)  # the last went out late: a period after it


def test_replay_woken_late_never_sends_two_frames_closer_than_a_period(monkeypatch):
    from nodes import replay

    clock = {"now": 100.0}
    sent: list[tuple[float, list[float]]] = []

    class LateBody:  # the clock moves only as the node waits; one wait comes back 0.5 s late
        def __init__(self):
            self.waits = 0

        def state_deg(self):
            return np.zeros(6)

        reached_deg = state_deg

        def wait_until(self, deadline):
            self.waits += 1
            clock["now"] = max(clock["now"], deadline) + (0.5 if self.waits == 20 else 0.0)

        def send(self, angles):
            sent.append((clock["now"], list(angles)))

    monkeypatch.setattr(replay.time, "monotonic", lambda: clock["now"])
    actions = np.zeros((40, 6))
    actions[:, 0] = np.linspace(30, 60, 40)  # 30 fps, the first frame 30° away: a 1 s ramp
    replay.play(LateBody(), actions, 30, replay.TEXT["en"])
    times = np.array([when for when, _ in sent])
    assert len(sent) == 30 + 40 and np.diff(times).min() >= 1 / 30 - 1e-9
    pan = np.array([angles[0] for _, angles in sent])
    assert np.max(np.diff(pan[:30]) / np.diff(times[:30])) <= 30 + 1e-6  # the ramp's 30°/s, late or not


def test_tracking_error_line():
    actions = np.zeros((100, 6))
    reached = np.zeros((100, 6))
    reached[:, 0] = np.linspace(0, 9.9, 100)
    errors = tracking_errors_deg(actions, reached)
    assert tracking_line(errors) == "tracking error (deg): p50 0.00, p99 9.30, max 9.90"  # 600 values, 501 of them 0
    with pytest.raises(ValueError):
        tracking_errors_deg(actions, reached[:, :5])


# -- the dataflows ----------------------------------------------------------------------------------

def test_record_adds_the_recorder_and_the_camera_and_wires_the_prompt():
    descriptor = with_recorder(dataflow_copy({}), "simulation", {"SO101_RECORD_DIR": "/d"}, {"SO101_RECORD_IMAGE_SIZE": "320x240"}, 30)
    nodes = {node["id"]: node for node in descriptor["nodes"]}
    assert "joint_target" in nodes["simulation"]["outputs"]
    assert nodes["keyboard_control"]["outputs"] == ["joint_cmd", "record_cmd"]
    assert nodes["keyboard_control"]["inputs"]["record_status"]["source"] == "recorder/record_status"
    assert nodes["recorder"]["inputs"]["image"]["source"] == "camera/image"
    assert nodes["recorder"]["inputs"]["joint_target"]["source"] == "simulation/joint_target"
    assert nodes["camera"]["inputs"]["tick"]["source"] == "dora/timer/millis/33"
    assert nodes["recorder"]["path"].endswith("nodes/recorder.py") and nodes["recorder"]["env"] == {"SO101_RECORD_DIR": "/d"}


def test_the_web_view_reads_the_camera_the_recorders_status_and_the_tasks_layouts_where_there_are_some():
    bare = {node["id"]: node for node in with_web_view(dataflow_copy({}), "simulation", {})["nodes"]}
    assert set(bare["web_view"]["inputs"]) == {"joint_state", "gripper_state"}
    recording = with_recorder(dataflow_copy({}), "simulation", {}, {"SO101_RECORD_IMAGE_SIZE": "320x240"}, 30)
    nodes = {node["id"]: node for node in with_web_view(recording, "simulation", {"SO101_WEB_PORT": "8200"})["nodes"]}
    inputs = nodes["web_view"]["inputs"]
    assert {name: spec["source"] for name, spec in inputs.items()} == {
        "joint_state": "simulation/joint_state", "gripper_state": "simulation/gripper_state",
        "image": "camera/image", "record_status": "recorder/record_status"}
    assert nodes["web_view"]["env"] == {"SO101_WEB_PORT": "8200"} and "outputs" not in nodes["web_view"]
    tasked = with_web_view(with_task(dataflow_copy({}), "simulation", "cube_to_box", 3), "simulation", {})
    web_view = next(node for node in tasked["nodes"] if node["id"] == "web_view")
    assert {name: spec["source"] for name, spec in web_view["inputs"].items() if name.endswith("_state") or name == "task_status"} == {
        "joint_state": "simulation/joint_state", "gripper_state": "simulation/gripper_state",
        "object_state": "simulation/object_state", "task_status": "simulation/task_status"}  # the seed: each layout's look
    assert web_view["env"] == {"SO101_TASK": "cube_to_box"}


def test_a_policy_that_sees_and_the_recorder_share_one_camera_at_the_higher_rate():
    descriptor = with_task(dataflow_copy({}), "simulation", "cube_to_box", 3)
    with_camera(descriptor, "simulation", {"SO101_RECORD_IMAGE_SIZE": "96x72"}, 25)
    with_policy(descriptor, "simulation", ("joint_state", "gripper_state", "image", "wrist_image"), {}, "/py")
    with_recorder(descriptor, "simulation", {}, {"SO101_RECORD_IMAGE_SIZE": "96x72", "SO101_SCENARIO": '{"looks":"varied"}'}, 30)
    nodes = {node["id"]: node for node in descriptor["nodes"]}
    assert [node["id"] for node in descriptor["nodes"]].count("camera") == 1
    camera = nodes["camera"]
    assert camera["outputs"] == ["image", "wrist_image"] and camera["inputs"]["tick"]["source"] == "dora/timer/millis/33"
    assert camera["env"] == {"SO101_RECORD_IMAGE_SIZE": "96x72", "SO101_TASK": "cube_to_box",
                             "SO101_SCENARIO": '{"looks":"varied"}'}
    # The policy takes the newest picture only; the recorder, every one.
    assert nodes["policy"]["inputs"]["image"] == {"source": "camera/image", "queue_size": 1}
    assert nodes["policy"]["inputs"]["wrist_image"] == {"source": "camera/wrist_image", "queue_size": 1}
    assert nodes["policy"]["inputs"]["joint_state"]["source"] == "simulation/joint_state"
    assert nodes["recorder"]["inputs"]["wrist_image"]["source"] == "camera/wrist_image"


def test_record_without_a_camera_has_no_image_input():
    descriptor = with_recorder(dataflow_copy({}), "simulation", {}, None, 30)
    nodes = {node["id"]: node for node in descriptor["nodes"]}
    assert "camera" not in nodes and "image" not in nodes["recorder"]["inputs"]


def test_replay_takes_the_prompts_place():
    descriptor = with_replay(dataflow_copy({}), "simulation")
    nodes = {node["id"]: node for node in descriptor["nodes"]}
    assert "keyboard_control" not in nodes and nodes["replay"]["path"] == "dynamic"
    assert nodes["simulation"]["inputs"]["joint_cmd"]["source"] == "replay/joint_cmd"
    assert DATAFLOW_FILE.read_text().count("keyboard_control/joint_cmd") == 1  # the course's file is untouched


# -- the body's joint_target ----------------------------------------------------------------------

def test_a_body_publishes_its_targets_only_where_the_dataflow_declares_them(monkeypatch):
    events = [TICK, ("joint_cmd", pa.array([0, 45])), TICK, TICK]
    code, node = run_simulation_node(monkeypatch, events)
    assert code == 0 and "joint_target" not in node.outputs
    config = dict(TICK_TIMER_CONFIG, outputs=["joint_state", "gripper_state", "image", "joint_target"])
    code, node = run_simulation_node(monkeypatch, events, node_config=config)
    targets = [message.to_pylist() for message in node.outputs["joint_target"]]
    assert targets == [[0.0] * 6, [45.0, 0, 0, 0, 0, 0]]  # the first tick's, then the change's; not the third tick's


def test_encoding_a_video_leaves_no_thread_of_this_process_real_time(tmp_path):
    """SVT-AV1 sets real-time policies where it may (as root), the encoding process's main thread
    included: left so, this test process's main thread starved every later test's emulated arm."""
    import os

    from so101.dataset.video import StreamingEncoder

    encoder = StreamingEncoder(tmp_path / "episode.mp4", 30, 64, 48)
    for value in range(10):
        encoder.add(np.full((48, 64, 3), value * 20, dtype=np.uint8))
    assert encoder.finish().frames == 10
    policies = {}
    for task in os.listdir("/proc/self/task"):
        try:
            policies[task] = os.sched_getscheduler(int(task))
        except ProcessLookupError:
            pass
    assert not set(policies.values()) & {os.SCHED_FIFO, os.SCHED_RR}, policies


def test_a_task_adds_its_outputs_to_the_body_its_line_to_the_prompt_and_its_objects_to_the_web_view():
    from so101.runtime.dataflow import with_task

    descriptor = with_web_view(with_task(dataflow_copy({}), "simulation", "cube_to_box", 5), "simulation",
                               {"SO101_WEB_PORT": "8200"})
    nodes = {node["id"]: node for node in descriptor["nodes"]}
    body, prompt, web = nodes["simulation"], nodes["keyboard_control"], nodes["web_view"]
    assert body["env"]["SO101_TASK"] == "cube_to_box" and body["env"]["SO101_SEED"] == "5"
    assert body["outputs"][-2:] == ["object_state", "task_status"]
    assert body["inputs"]["task_cmd"]["source"] == "keyboard_control/task_cmd"
    assert prompt["outputs"] == ["joint_cmd", "task_cmd"]
    assert {prompt["inputs"][name]["source"] for name in ("task_status", "object_state")} == {
        "simulation/task_status", "simulation/object_state"}
    assert web["inputs"]["object_state"]["source"] == "simulation/object_state"
    assert web["env"] == {"SO101_WEB_PORT": "8200", "SO101_TASK": "cube_to_box"}  # the task the body runs



def test_a_tasks_frames_hold_its_objects_reward_and_success_from_the_first_object_state_on():
    from so101.dataset.features import ENVIRONMENT_KEY, REWARD_KEY, SUCCESS_KEY
    from so101.tasks import CUBE_TO_BOX

    rec, writer, clock, said = recording(task=CUBE_TO_BOX)
    assert not rec.needs_wrist_image  # no video: no wrist picture either
    record_for(rec, clock, "put the cube in the box", 0.2)
    assert rec.episode.frames == 0  # no object_state yet: no frame
    objects = [0.2, -0.1, 0.0125, 0, 0, 0, 1, 0.16, 0.19, 0]
    rec.on_object_state(objects[:9])  # not this task's: ignored
    feed(rec, clock, 0.1)
    assert rec.episode.frames == 0
    rec.on_object_state(objects)
    feed(rec, clock, 0.5)
    rec.on_task_status(True)
    rec.on_object_state([0.16, 0.19, 0.0175, 0, 0, 0, 1, 0.16, 0.19, 0])
    feed(rec, clock, 0.2)
    frames = rec.episode.frames_given
    first, last = frames[0], frames[-1]
    assert first[ENVIRONMENT_KEY].dtype == np.float32 and np.allclose(first[ENVIRONMENT_KEY], objects)
    assert first[REWARD_KEY].tolist() == [0.0] and first[SUCCESS_KEY].tolist() == [False]
    assert last[REWARD_KEY].dtype == np.float32 and last[REWARD_KEY].tolist() == [1.0]
    assert last[SUCCESS_KEY].dtype == np.bool_ and last[SUCCESS_KEY].tolist() == [True]
    assert np.allclose(last[ENVIRONMENT_KEY][0:3], [0.16, 0.19, 0.0175])
    assert 20 <= len(frames) <= 22  # 0.7 s at 30 fps, counted from the first object_state


def test_record_with_a_task_gives_the_recorder_the_bodys_objects_and_success():
    from so101.runtime.dataflow import with_task

    descriptor = with_recorder(with_task(dataflow_copy({}), "simulation", "cube_to_box", 0), "simulation",
                               {"SO101_RECORD_DIR": "/d"}, {"SO101_RECORD_IMAGE_SIZE": "96x72"}, 30)
    nodes = {node["id"]: node for node in descriptor["nodes"]}
    recorder, camera = nodes["recorder"], nodes["camera"]
    assert recorder["inputs"]["object_state"]["source"] == "simulation/object_state"
    assert recorder["inputs"]["task_status"]["source"] == "simulation/task_status"
    assert recorder["env"] == {"SO101_RECORD_DIR": "/d", "SO101_TASK": "cube_to_box"}
    assert camera["inputs"]["object_state"]["source"] == "simulation/object_state"
    assert camera["inputs"]["task_status"]["source"] == "simulation/task_status"  # its seed: the looks'
    assert camera["env"] == {"SO101_RECORD_IMAGE_SIZE": "96x72", "SO101_TASK": "cube_to_box"}
    assert camera["outputs"] == ["image", "wrist_image"]
    assert recorder["inputs"]["wrist_image"]["source"] == "camera/wrist_image"



def test_a_tasks_frames_with_video_wait_for_both_cameras():
    from so101.dataset.features import WRIST_IMAGE_KEY
    from so101.tasks import CUBE_TO_BOX

    rec, writer, clock, said = recording(needs_image=True, task=CUBE_TO_BOX)
    rec.on_object_state([0.2, -0.1, 0.0125, 0, 0, 0, 1, 0.16, 0.19, 0])
    front = np.zeros((240, 320, 3), np.uint8)
    wrist = np.full((240, 320, 3), 7, np.uint8)
    rec.on_image(front)
    record_for(rec, clock, "put the cube in the box", 0.2)
    assert rec.episode.frames == 0  # the wrist camera has not drawn yet
    rec.on_wrist_image(wrist)
    feed(rec, clock, 0.2)
    assert rec.episode.frames > 0
    assert rec.episode.frames_given[0][WRIST_IMAGE_KEY] is wrist and rec.episode.frames_given[0][IMAGE_KEY] is front


def test_a_picture_size_is_width_x_height_in_even_pixels():
    import argparse

    from so101.runtime.argtypes import image_size

    assert image_size("640x480") == (640, 480) and image_size(" 320X240 ") == (320, 240)
    for bad in ("641x480", "640", "x", "", "8x8", "640x480x3"):
        with pytest.raises(argparse.ArgumentTypeError, match=r"is not WIDTHxHEIGHT in even pixels from 16 to 4096, e.g. 640x480$"):
            image_size(bad)
