"""Real cameras without a camera: the plain rules (`--camera NAME=SOURCE`, scaling, capture times, the
listing from a fake sysfs tree), the capture against video files that carry their frame numbers
(tests/helpers/numbered_video.py), the recorder pairing pictures with states and ending an episode
whose camera stopped, and `so101 teleop --body real --camera ...` in tmux on the emulated arm."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from so101.cameras.capture import Capturing, VideoSource
from so101.cameras.listing import CameraFound, find_cameras, listing_lines
from so101.cameras.sources import (
    CAMERA_SILENT_S, cameras_given, capture_source, capture_time_s, parse_camera_option, scaled_size, silent_camera,
    source_problem,
)
from so101.cameras.v4l2 import Mode
from so101.dataset.features import IMAGE_KEY, STATE_KEY, WRIST_IMAGE_KEY, from_lerobot
from so101.dataset.messages import RecordCommand
from so101.dataset.recording import Recording, nearest_in_time
from so101.launch.real_cameras import add_real_cameras, policy_picture_problem
from so101.observe import parse_observed
from so101.runtime.dataflow import dataflow_copy, with_policy, with_recorder, with_web_view
from tests.helpers.dataflow import SO101
from tests.helpers.numbered_video import frame_number, numbered_frame, video_frame_numbers, write_numbered_video
from tests.test_recording import Clock, FakeWriter

# -- the plain rules ---------------------------------------------------------------------------------------------


def test_a_camera_option_is_a_name_and_a_source():
    assert parse_camera_option("front=/dev/video0") == ("front", "/dev/video0")
    assert parse_camera_option(" wrist = 2 ") == ("wrist", "2")
    assert capture_source("2") == 2 and capture_source("/dev/video2") == "/dev/video2"
    assert cameras_given([("wrist", "2"), ("front", "0")]) == {"front": "0", "wrist": "2"}


@pytest.mark.parametrize("text, message", [
    ("front", "'front' is not NAME=SOURCE: e.g. front=/dev/video0, wrist=2 or front=demo.mp4"),
    ("front=", "'front=' is not NAME=SOURCE"),
    ("top=/dev/video0", "'top' is not a camera's name here: front or wrist"),
])
def test_a_bad_camera_option_says_what_is_accepted(text, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        parse_camera_option(text)


def test_a_camera_given_twice_or_a_missing_file_is_refused(tmp_path):
    with pytest.raises(ValueError, match="given twice"):
        cameras_given([("front", "0"), ("front", "1")])
    assert source_problem(capture_source("0")) is None and source_problem("/dev/video9") is None  # it may come later
    assert source_problem(str(tmp_path / "none.mp4")) == f"{tmp_path / 'none.mp4'} is neither a camera " \
                                                         "(an index, /dev/videoN) nor a video file"


def test_pictures_are_scaled_only_within_their_shape():
    assert scaled_size((640, 480), (640, 480)) is None
    assert scaled_size((640, 480), (32, 24)) == (32, 24)
    assert scaled_size((1280, 720), (640, 360)) == (640, 360)
    with pytest.raises(ValueError, match=r"96x96 pictures cannot be made from the camera's 640x480 without distorting"):
        scaled_size((640, 480), (96, 96))


def test_a_capture_time_is_the_drivers_where_it_is_plausible():
    # The driver's buffer stamp (monotonic ms) 20 ms before now: the picture is 20 ms old on the wall clock.
    assert capture_time_s(1000.0, 50.0, 49_980.0) == pytest.approx(999.98)
    assert capture_time_s(1000.0, 50.0, 0.0) == 1000.0  # a file's position, or no stamp: when it was read
    assert capture_time_s(1000.0, 50.0, 60_000.0) == 1000.0  # in the future: not a monotonic stamp


def test_the_listing_reads_a_sysfs_tree_and_skips_nodes_that_capture_nothing(tmp_path):
    for number, name in ((0, "USB Camera: front"), (1, "USB Camera: front"), (2, "Arducam: wrist")):
        (tmp_path / f"video{number}").mkdir()
        (tmp_path / f"video{number}" / "name").write_text(name + "\n")
    modes = {"/dev/video0": [Mode("MJPG", 640, 480, (30.0, 15.0)), Mode("MJPG", 1280, 720, (30.0,)),
                             Mode("YUYV", 640, 480, (30.0,))],
             "/dev/video2": [Mode("MJPG", 640, 480, (60.0, 30.0))]}
    found = find_cameras(tmp_path, modes.get)
    assert [camera.path for camera in found] == ["/dev/video0", "/dev/video2"]  # video1: a metadata node
    assert listing_lines(found) == [
        "/dev/video0  USB Camera: front",
        "    MJPG 1280x720  30 fps",
        "    MJPG 640x480  30, 15 fps",
        "    YUYV 640x480  30 fps",
        "/dev/video2  Arducam: wrist",
        "    MJPG 640x480  60, 30 fps",
    ]
    assert find_cameras(tmp_path / "none") == []
    assert listing_lines([]) == ["no cameras: no V4L2 capture device under /dev/video* (plugged in? `ls /dev/video*`; "
                                 "a video file works as a camera: --camera front=FILE)"]
    assert listing_lines([CameraFound("/dev/video4", "odd", ())])[1] == "    (it lists no sizes)"


def test_so101_cameras_says_no_cameras_in_one_line_here():
    done = subprocess.run([str(SO101), "cameras", "--save", "/nonexistent/pictures"], capture_output=True, text=True,
                          timeout=60)
    if Path("/dev/video0").exists():
        pytest.skip("this machine has a camera")
    assert done.returncode == 0 and done.stderr == "" and done.stdout.startswith("no cameras: ") \
        and len(done.stdout.splitlines()) == 1, done.stdout + done.stderr


# -- the capture, on video files ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def numbered_video(tmp_path_factory) -> Path:
    """1000 frames (33 s at 30 fps), 640x480, each showing its number."""
    return write_numbered_video(tmp_path_factory.mktemp("video") / "numbered.mp4", 1000)


def test_the_numbers_survive_the_file(numbered_video):
    assert frame_number(numbered_frame(613, 32, 24)) == 613
    assert video_frame_numbers(numbered_video)[:300] == list(range(300))


def test_a_file_plays_at_its_own_rate_in_order_and_scaled(tmp_path):
    video = write_numbered_video(tmp_path / "short.mp4", 45)
    source = VideoSource(str(video), (320, 240), None, 30)
    assert source.open() is None
    started = time.monotonic()
    pictures = []
    while (read := source.read()) is not None:
        pictures.append(read)
    took_s = time.monotonic() - started
    source.close()
    assert [frame_number(rgb) for rgb, _ in pictures] == list(range(45))
    assert all(rgb.shape == (240, 320, 3) for rgb, _ in pictures)
    assert 1.3 < took_s < 2.5, took_s  # 45 frames at 30 a second: 1.5 s
    gaps = np.diff([captured for _, captured in pictures])
    assert abs(float(np.median(gaps)) - 1 / 30) < 0.005, gaps
    squeezed = VideoSource(str(video), (96, 96), None, 30)
    assert squeezed.open() is None
    with pytest.raises(ValueError, match="without distorting"):
        squeezed.read()
    squeezed.close()


class ScriptedSource:
    """A camera that gives `gives` pictures, stops, cannot be opened `absent` times, then gives pictures again."""

    def __init__(self, gives: int, absent: int):
        self.gives, self.absent, self.opened, self.read_count = gives, absent, 0, 0

    def open(self):
        self.opened += 1
        if 1 < self.opened <= 1 + self.absent:
            return "it cannot be opened"
        return None

    def read(self):
        self.read_count += 1
        if self.opened == 1 and self.read_count > self.gives:
            return None
        time.sleep(0.001)
        return np.zeros((4, 4, 3), np.uint8), time.time()

    def close(self):
        pass


def test_a_camera_that_stops_is_said_once_tried_again_and_said_back():
    said: list[str] = []
    source = ScriptedSource(gives=5, absent=3)
    capturing = Capturing(source, "front", "/dev/video0", said.append, retry_s=0.01)
    capturing.start()
    deadline = time.monotonic() + 5
    while (capturing.latest is None or capturing.latest.number < 20) and time.monotonic() < deadline:
        time.sleep(0.01)
    capturing.stop()
    assert said == ["camera front: /dev/video0 stopped (no picture came: unplugged, or the file ended); trying it "
                    "again every 0.01 s", "camera front: /dev/video0 is back"]
    assert capturing.latest is not None and capturing.latest.number >= 20  # numbered on across the reconnection


# -- the recorder: pictures paired with states, and a camera that stops ------------------------------------------


def camera_recording(camera_lost="save"):
    said: list[str] = []
    logged: list[str] = []
    clock, writer = Clock(), FakeWriter()
    rec = Recording(writer, "/data/set", 30, "en", True, said.append, clock, observed=parse_observed("state,front,wrist"),
                    wrist=True, camera_lost=camera_lost, log=logged.append)
    return rec, writer, clock, said, logged


def test_a_camera_has_stopped_once_its_newest_picture_is_over_half_a_second_old_and_one_not_yet_seen_is_awaited():
    # The one rule the recorder (ending an episode) and a policy that sees (ending its drive) share.
    arrived_s = {"front": 10.0, "wrist": 10.3}
    assert CAMERA_SILENT_S == 0.5
    assert silent_camera(arrived_s, ("front", "wrist"), 10.5) is None  # 0.5 s: a late frame, not yet stopped
    assert silent_camera(arrived_s, ("front", "wrist"), 10.6) == ("front", pytest.approx(0.6))
    assert silent_camera(arrived_s, ("wrist", "front"), 10.9) == ("wrist", pytest.approx(0.6))  # the first needed
    assert silent_camera(arrived_s, ("wrist",), 10.6) is None  # only the cameras needed count
    assert silent_camera({}, ("front", "wrist"), 99.0) is None  # none has sent yet: waited for


def test_nearest_in_time_picks_the_closest_sample():
    history = [(1.00, "a"), (1.02, "b"), (1.04, "c")]
    assert nearest_in_time(history, 1.029) == (1.02, "b") and nearest_in_time(history, 1.031) == (1.04, "c")
    assert nearest_in_time(history, 0.5) == (1.00, "a") and nearest_in_time(history, 9.0) == (1.04, "c")
    assert nearest_in_time([], 1.0) is None


def test_each_picture_is_paired_with_the_state_of_its_capture():
    rec, writer, clock, said, logged = camera_recording()
    picture = np.zeros((24, 32, 3), np.uint8)
    # The arm at 50 states a second, pan = 100 x the time it was sent; a picture captured at 10.013 s.
    for step in range(50):
        sent_s = 10.0 + step * 0.02
        rec.on_joint_state([100 * sent_s, 0, 0, 0, 0], sent_s)
        rec.on_gripper_state([0.0], sent_s)
    rec.command(RecordCommand("record", "look"))
    rec.on_image(picture, 10.013)
    rec.on_wrist_image(picture, 10.013)
    clock.now_s += 0.01
    assert rec.tick() == 1
    state_deg = from_lerobot(writer.saved[0].rows[0][0] if writer.saved else rec.episode.rows[0][0])
    assert state_deg[0] == pytest.approx(1002.0, abs=1e-3)  # the state sent at 10.02 s, not the latest (10.98 s)
    assert IMAGE_KEY in rec.episode.frames_given[0] and WRIST_IMAGE_KEY in rec.episode.frames_given[0]
    rec.command(RecordCommand("stop", ""))
    assert logged == ["episode 0: each picture paired with the state sent nearest its capture, at most 7 ms apart"]


@pytest.mark.parametrize("choice, result", [("save", r"■ episode 0: \d+ frames \(\d\.\d s\), saving\.\.\."),
                                            ("discard", r"episode 0 discarded \(\d+ frames\)")])
def test_a_camera_that_stops_ends_the_episode_kept_or_dropped_as_chosen(choice, result):
    rec, writer, clock, said, _ = camera_recording(choice)
    picture = np.zeros((24, 32, 3), np.uint8)
    rec.on_joint_state([1.0, 2.0, 3.0, 4.0, 5.0])
    rec.on_gripper_state([0.0])
    rec.command(RecordCommand("record", "look"))
    for _ in range(30):  # 1 s of both cameras
        clock.now_s += 1 / 30
        rec.on_image(picture)
        rec.on_wrist_image(picture)
        rec.tick()
    frames = rec.episode.frames
    for _ in range(30):  # the wrist camera goes on; the front one is silent
        clock.now_s += 1 / 30
        rec.on_wrist_image(picture)
        rec.tick()
    rec.close()
    assert rec.episode is None and len(said) == 2 - (choice == "discard"), said
    assert re.fullmatch(r"✗ the front camera sent no picture for 0\.5 s: " + result, said[0]), said
    kept = writer.saved[0].frames if writer.saved else 0
    assert (kept >= frames and kept <= frames + 16) if choice == "save" else kept == 0
    assert rec.command(RecordCommand("record", "again")) == [
        f"the front camera has sent no picture for {clock.now_s - 1:.1f} s: not recording (is it plugged in?)"]
    assert CAMERA_SILENT_S == 0.5


# -- the dataflow ------------------------------------------------------------------------------------------------


def test_each_real_camera_is_a_node_whose_pictures_the_recorder_policy_and_web_view_read():
    from so101.bodies.registry import BODIES

    body = BODIES["real"]
    descriptor = dataflow_copy({}, body.dataflow_file)
    add_real_cameras(descriptor, {"front": "/dev/video0", "wrist": "clip.mp4"}, (640, 480), (32, 24), 30)
    with_policy(descriptor, "arm", ("joint_state", "gripper_state", "image", "wrist_image"), {}, sys.executable)
    with_recorder(descriptor, "arm", {"SO101_RECORD_CAMERAS": "front,wrist"}, None, 30)
    with_web_view(descriptor, "arm", {})
    nodes = {node["id"]: node for node in descriptor["nodes"]}
    assert nodes["camera_front"]["env"] == {
        "CAPTURE_PATH": "/dev/video0", "IMAGE_WIDTH": "32", "IMAGE_HEIGHT": "24", "ENCODING": "rgb8",
        "SO101_CAMERA_NAME": "front", "SO101_CAMERA_SIZE": "640x480", "SO101_CAMERA_FPS": "30"}
    assert nodes["camera_wrist"]["outputs"] == ["image"] and "camera" not in nodes
    for reader in ("policy", "recorder"):
        assert nodes[reader]["inputs"]["image"]["source"] == "camera_front/image"
        assert nodes[reader]["inputs"]["wrist_image"]["source"] == "camera_wrist/image"
    assert nodes["web_view"]["inputs"]["image"]["source"] == "camera_front/image"


@pytest.mark.parametrize("needed, cameras, camera_size, recording, problem", [
    (("image", "wrist_image"), {"front": "0"}, (640, 480), False,
     "the policy sees the wrist camera, which is not given: add --camera front=SOURCE --camera wrist=SOURCE"),
    (("image",), {"front": "0"}, (640, 480), True,
     "the policy sees 32x24 pictures, and the cameras' pictures are recorded too: record at --camera-size 32x24, or "
     "run the policy without --record"),
    (("image",), {"front": "0"}, (640, 360), False,
     "the policy sees 32x24 pictures: 32x24 pictures cannot be made from the camera's 640x360 without distorting "
     "them: scaled, a picture keeps its shape (640:360); give --camera-size of the policy's shape"),
    (("image", "wrist_image"), {"front": "0", "wrist": "1"}, (640, 480), False, None),
])
def test_a_policy_whose_pictures_the_cameras_cannot_give_is_refused(needed, cameras, camera_size, recording, problem):
    assert policy_picture_problem(needed, cameras, camera_size, (32, 24), recording) == problem


@pytest.mark.parametrize("extra, last_line", [
    ("--camera front=0", "so101 teleop: --camera is for --body real: a simulated body draws its own front and wrist "
                         "cameras"),
    ("--camera top=0", "so101 teleop: error: argument --camera: 'top' is not a camera's name here: front or wrist "
                       "(the dataset's observation.images.front and .wrist)"),
])
def test_teleop_refuses_cameras_it_cannot_use_in_one_line(extra, last_line):
    done = subprocess.run([str(SO101), "teleop", "--mode", "direct", "--lang", "en", *extra.split()],
                          capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert done.returncode == 2 and done.stderr.strip().splitlines()[-1] == last_line, done.stderr
