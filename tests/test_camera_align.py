"""`so101 cameras --align NAME`: the words that say which way to move a camera (exact), the overlay of the
simulated arm on a picture and how well they agree, the command's refusals in one line, and one run on the
emulated arm (`so101 fake-arm`'s bus, in its own process) with a video file as the camera: the lines it says,
a browser page that serves, and torque off at the end with no goal ever written."""

from __future__ import annotations

import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from so101.bodies.camera_file import CameraFile, default_camera_file, front_file_of, orbit_of
from so101.camera_pose.overlay import OUTLINE_RGB, outline_of, outline_on_edges, overlay_picture
from so101.camera_pose.moves import move_in_words

SO101 = Path(sys.executable).parent / "so101"
# The arm where the emulated one is moved by hand, and the tests draw it: all of it in the front camera's picture.
POSE_DEG = (-15.0, 0.0, 20.0, 60.0, 10.0, 25.0)
# A task's objects far off the picture: a real scene has none of them.
OBJECTS_AWAY = (3.0, 3.0, 0.0125, 0.0, 0.0, 0.0, 1.0, 3.0, 3.0, 0.0)
SIZE = (320, 240)

# A camera 30 cm up at the origin, looking along +x (its right is -y), and that camera moved or turned.
LEVEL = CameraFile("front", (0.0, 0.0, 0.3), (1.0, 0.0, 0.3), (0.0, 0.0, 1.0), 45.0)


def _turned(degrees: float, axis: str) -> CameraFile:
    tangent = math.tan(math.radians(degrees))
    if axis == "pan":  # toward -y: the camera's right
        return replace(LEVEL, look_at_m=(1.0, -tangent, 0.3))
    if axis == "tilt":
        return replace(LEVEL, look_at_m=(1.0, 0.0, 0.3 + tangent))
    return replace(LEVEL, up=(0.0, -math.sin(math.radians(degrees)), math.cos(math.radians(degrees))))


@pytest.mark.parametrize("current, target, words", [
    (LEVEL, LEVEL, "in place"),
    (LEVEL, replace(LEVEL, position_m=(0.0, -0.021, 0.3), look_at_m=(1.0, -0.021, 0.3)), "move the camera 2.1 cm right"),
    (LEVEL, replace(LEVEL, position_m=(-0.012, 0.021, 0.308), look_at_m=(0.988, 0.021, 0.308)),
     "move the camera 2.1 cm left, 0.8 cm up, 1.2 cm back"),
    (LEVEL, _turned(3.0, "pan"), "turn the camera 3° right"),
    (LEVEL, _turned(-2.0, "tilt"), "tilt the camera 2° down"),
    (LEVEL, _turned(1.0, "roll"), "roll the camera 1° clockwise"),
    (LEVEL, _turned(-1.5, "roll"), "roll the camera 1.5° anticlockwise"),
    (replace(LEVEL, fov_deg=49.0), LEVEL, "zoom: field of view 4° wider than the simulated one's"),
    (LEVEL, replace(LEVEL, fov_deg=47.5), "zoom: field of view 2.5° narrower than the simulated one's"),
    (replace(LEVEL, fov_deg=49.0),
     replace(_turned(-2.0, "tilt"), position_m=(0.0, 0.0, 0.29), look_at_m=(1.0, 0.0, 0.29 - math.tan(math.radians(2.0)))),
     "move the camera 1 cm down; tilt it 2° down; zoom: field of view 4° wider than the simulated one's"),
    # Below a hand's reach (1.9 mm, 0.25°): nothing to do.
    (LEVEL, replace(_turned(0.25, "pan"), position_m=(0.0019, 0.0, 0.3)), "in place"),
])
def test_move_in_words_says_the_way_in_the_cameras_own_terms(current: CameraFile, target: CameraFile, words: str):
    assert move_in_words(current, target) == words


def test_move_in_words_turns_a_turned_front_camera_back():
    """The default front camera (50° down, 60 cm from its aim) orbited 8° about the vertical through its aim,
    and fitted there: back is the chord (2 x 38.6 cm x sin 4° = 5.4 cm, 4° off its right: 0.4 cm toward its
    aim, 0.3 up and 0.2 forward), then 8° about the vertical, a pan (8° cos 50°) and a roll (8° sin 50°)."""
    default = default_camera_file("front")
    fitted = front_file_of(replace(orbit_of(default), yaw_deg=orbit_of(default).yaw_deg + 8.0), *SIZE)
    assert move_in_words(fitted, default) == ("move the camera 5.4 cm left, 0.3 cm up, 0.2 cm forward; turn it 5.1° right; "
                                              "roll it 6.1° clockwise")


@pytest.fixture(scope="module")
def drawn_arm():
    """The arm at POSE_DEG from the default front camera: (picture, the mask of the arm's pixels)."""
    from so101.runtime.display import choose_mujoco_gl

    choose_mujoco_gl()
    from so101.bodies.task_cameras import TaskCameras
    from so101.tasks import task_named

    with TaskCameras(task_named("cube_to_box"), looks="fixed") as cameras:
        picture, _ = cameras.draw(POSE_DEG, OBJECTS_AWAY, *SIZE, wrist=False)
        mask = cameras.arm_mask(POSE_DEG, cameras.front_camera(), *SIZE)
    return picture, mask


@pytest.mark.slow  # draws the arm
def test_the_arm_over_its_own_picture_agrees_and_shifted_it_does_not(drawn_arm):
    picture, mask = drawn_arm
    assert mask.mean() > 0.05  # the arm is in the picture
    assert outline_on_edges(picture, mask) > 0.9
    # The camera 12 pixels off to one side and 8 down: most of the outline is off the arm's edges.
    assert outline_on_edges(np.roll(picture, (8, 12), axis=(0, 1)), mask) < 0.5
    assert outline_on_edges(picture, np.zeros_like(mask)) is None


@pytest.mark.slow  # draws the arm
def test_the_overlay_tints_the_arm_draws_its_outline_and_leaves_the_rest(drawn_arm):
    picture, mask = drawn_arm
    overlay = overlay_picture(picture, mask)
    assert overlay.shape == picture.shape and overlay.dtype == np.uint8
    outline = outline_of(mask, 1)  # 2 pixels wide at 640: 1 at 320
    assert (overlay[outline] == OUTLINE_RGB).all()
    assert (overlay[~mask] == picture[~mask]).all()
    inside = mask & ~outline
    # Tinted blue, where the arm is yellow.
    assert (overlay[inside].astype(int) - picture[inside].astype(int))[:, 2].mean() > 20
    assert (overlay_picture(picture, np.zeros_like(mask)) == picture).all()


def test_align_refuses_in_one_line(tmp_path: Path, capsys):
    from so101.cli.main import main

    camera_file = tmp_path / "front.json"
    camera_file.write_text('{"camera": "front", "position_m": [1, 2]}', encoding="utf-8")
    video = tmp_path / "front.mp4"
    video.write_bytes(b"not a video")
    for argv, said in (
        (["--camera", "front=0"], "--align needs the arm: --port PORT"),
        (["--camera", "wrist=0", "--port", "/dev/none", "--calibration", "c.json"],
         "--align front lines up the front camera"),
        (["--camera", f"front={tmp_path / 'missing.mp4'}", "--port", "/dev/none", "--calibration", "c.json"],
         "is neither a camera"),
        (["--camera", f"front={video}", "--port", "/dev/none", "--calibration", "c.json"],
         f"camera front: {video}: not a video (Invalid data found when processing input)"),
        (["--camera", f"front={video}", "--port", "/dev/none", "--calibration", "c.json", "--fitted", str(camera_file)],
         "--fitted " + str(camera_file) + ": `position_m` must be three numbers"),
    ):
        assert main(["cameras", "--align", "front", *argv]) == 2
        out, err = capsys.readouterr()
        assert out == "" and err.count("\n") == 1 and said in err, (argv, err)


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def _video_of(path: Path, picture: np.ndarray, frames: int = 10) -> Path:
    """An MPEG-4 file of `picture` held for `frames` frames at 10 fps (a codec every OpenCV build decodes)."""
    import av

    with av.open(str(path), "w") as container:
        stream = container.add_stream("mpeg4", rate=10)
        stream.width, stream.height, stream.pix_fmt = picture.shape[1], picture.shape[0], "yuv420p"
        stream.bit_rate = 2_000_000
        for _ in range(frames):
            for packet in stream.encode(av.VideoFrame.from_ndarray(picture, format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    return path


def _refusals_with_the_arm(tmp_path: Path, port: str, video: Path, capsys) -> None:
    """No calibration file, no arm on the port: one line each, 2."""
    from so101.cli.main import main

    calibration = str(tmp_path / "so101_follower.json")
    for argv, said in (
        (["--port", port, "--calibration", str(tmp_path / "none.json")], f"no calibration file {tmp_path / 'none.json'}"),
        (["--port", str(tmp_path / "no_such_port"), "--calibration", calibration],
         f"cannot open the serial port {tmp_path / 'no_such_port'}"),
    ):
        assert main(["cameras", "--align", "front", "--camera", f"front={video}", *argv]) == 2
        out, err = capsys.readouterr()
        assert out == "" and err.count("\n") == 1 and said in err, (argv, out, err)


@pytest.mark.emulated_hardware
def test_align_on_the_emulated_arm_with_a_file_camera(tmp_path: Path, capsys):
    """The arm held by torque at POSE_DEG, a video of it from a camera 4 cm and 8° off the simulated one, with
    its fitted file: the command says where it reads, sees and draws from and which way to move, serves the
    page, draws the overlay, and on Ctrl-C ends with torque off, 0, no goal written."""
    from so101.bodies.task_cameras import TaskCameras
    from so101.feetech.calibration import MOTOR_NAMES, save_calibration, steps_to_deg
    from so101.feetech.fake_arm import FakeArmProcess, calibrate_as_at_the_factory, physical_steps
    from so101.tasks import task_named

    default = default_camera_file("front", *SIZE)
    orbit = orbit_of(default)
    target = orbit.target_xyz_m
    offset = front_file_of(replace(orbit, target_xyz_m=(target[0], target[1] + 0.04, target[2]),
                                   yaw_deg=orbit.yaw_deg + 8.0, fov_deg=orbit.fov_deg + 4.0), *SIZE)
    fitted = tmp_path / "fitted_front.json"
    fitted.write_text(offset.as_json(), encoding="utf-8")
    with FakeArmProcess() as arm:
        calibration = calibrate_as_at_the_factory(arm)
        save_calibration(tmp_path / "so101_follower.json", calibration)
        for servo_id, angle in enumerate(POSE_DEG, start=1):
            arm.move_by_hand(servo_id, round(physical_steps(arm.mechanics(servo_id), angle)))
        angles = [steps_to_deg(index, arm.read_register(index + 1, "Present_Position"), calibration[name])
                  for index, name in enumerate(MOTOR_NAMES)]
        with TaskCameras(task_named("cube_to_box"), looks="fixed", poses={"front": offset}) as cameras:
            picture, _ = cameras.draw(angles, OBJECTS_AWAY, *SIZE, wrist=False)
        video = _video_of(tmp_path / "front.mp4", picture)
        _refusals_with_the_arm(tmp_path, arm.port, video, capsys)
        for servo_id in range(1, 7):
            # Torque on where the joint stands (it holds still): the command must switch it off.
            arm.write_register(servo_id, "Goal_Position", arm.read_register(servo_id, "Present_Position"))
            arm.write_register(servo_id, "Torque_Enable", 1)
        web_port = _free_port()
        env = {key: value for key, value in os.environ.items() if key != "DISPLAY"}
        command = subprocess.Popen(
            [str(SO101), "cameras", "--align", "front", "--port", arm.port, "--calibration",
             str(tmp_path / "so101_follower.json"), "--camera", f"front={video}", "--fitted", str(fitted),
             "--web-port", str(web_port)],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
        lines: list[str] = []
        overlay_drawn = threading.Event()

        def read_lines() -> None:
            assert command.stdout is not None
            for line in command.stdout:
                lines.append(line.rstrip("\n"))
                if line.startswith("overlay live: "):
                    overlay_drawn.set()

        reader = threading.Thread(target=read_lines, daemon=True)
        reader.start()
        try:
            assert overlay_drawn.wait(60), lines
            assert [arm.read_register(servo_id, "Torque_Enable") for servo_id in range(1, 7)] == [0] * 6
            with urllib.request.urlopen(f"http://127.0.0.1:{web_port}/", timeout=10) as page:
                assert page.status == 200
            # Torque on again behind its back (a person's mistake elsewhere): the way out switches it off too.
            for servo_id in range(1, 7):
                arm.write_register(servo_id, "Torque_Enable", 1)
            time.sleep(0.5)  # a few refreshes more
            command.send_signal(signal.SIGINT)
            assert command.wait(30) == 0, lines
        finally:
            if command.poll() is None:
                command.kill()
                command.wait()
        reader.join(5)
        assert [arm.read_register(servo_id, "Torque_Enable") for servo_id in range(1, 7)] == [0] * 6
        assert all(arm.goals_written(servo_id) == () for servo_id in range(1, 7))
    assert lines == [
        f"arm on {arm.port}: read only, torque off: move it by hand",
        f"camera front: {video}, 320x240",
        "simulated front camera: the simulator's own (so101 cameras --default front)",
        f"to stand where the simulated front camera stands: {move_in_words(offset, default)}",
        f"browser view: http://127.0.0.1:{web_port}/",
        "no display (DISPLAY is not set or not reachable): no window; the browser view shows the overlay",
        lines[6],
        "stopped (Ctrl-C): torque off on servos 1-6, camera front closed",
    ], lines
    assert lines[6].startswith("overlay live: ") and lines[6].endswith("% of the simulated arm's outline lies on the "
                                                                       "picture's edges; Ctrl-C ends")
    assert "8.3 cm left" in lines[3] and "zoom: field of view 4° wider" in lines[3]
