"""Saved poses: persisted as JSON, written atomically, a bad file moved aside and reported, never overwritten."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time

import pytest

from so101.prompt.poses import Pose, PoseStore


def test_saved_poses_survive_a_new_store(tmp_path):
    path = tmp_path / "poses.json"
    store = PoseStore(path)
    assert store.names() == [] and store.load_notice is None and not path.exists()
    assert store.save("a", Pose((-30.0, 45.0, -60.0, 30.0, 0.0), 12.5)) is None
    assert store.save("b", Pose((1.0, 2.0, 3.0, 4.0, 5.0))) is None

    assert json.loads(path.read_text()) == {
        "a": {"joints_deg": [-30.0, 45.0, -60.0, 30.0, 0.0], "gripper_deg": 12.5},
        "b": {"joints_deg": [1.0, 2.0, 3.0, 4.0, 5.0], "gripper_deg": None},
    }
    again = PoseStore(path)
    assert again.names() == ["a", "b"]
    assert again.get("a").joint_cmd_deg() == (-30.0, 45.0, -60.0, 30.0, 0.0, 12.5)
    assert again.get("b").joint_cmd_deg() == (1.0, 2.0, 3.0, 4.0, 5.0)


def test_saving_again_replaces_the_pose_and_leaves_no_temporary_file(tmp_path):
    path = tmp_path / "poses.json"
    store = PoseStore(path)
    store.save("a", Pose((0.0,) * 5))
    store.save("a", Pose((10.0,) * 5))
    assert json.loads(path.read_text())["a"]["joints_deg"] == [10.0] * 5
    assert sorted(os.listdir(tmp_path)) == ["poses.json"]


def test_chinese_pose_names_are_kept_readable(tmp_path):
    path = tmp_path / "poses.json"
    PoseStore(path).save("抓取位", Pose((0.0,) * 5))
    assert "抓取位" in path.read_text(encoding="utf-8")
    assert PoseStore(path).names() == ["抓取位"]


@pytest.mark.parametrize(
    "content, problem",
    [
        (b'{"a": {"joints_deg": [1, 2', "is not a valid poses file"),
        (b"\xff\xfe not utf-8", "is not a valid poses file"),
        (b"[1, 2, 3]", "expected a JSON object of poses"),
        (b'{"a": {"joints_deg": [1, 2, 3]}}', "pose 'a' has no list of 5 finite numbers"),
        (b'{"a": {"joints_deg": [1, 2, 3, 4, "x"]}}', "pose 'a' has no list of 5 finite numbers"),
        (b'{"a": {"joints_deg": [1, 2, 3, 4, NaN]}}', "pose 'a' has no list of 5 finite numbers"),
        (b'{"a": {"joints_deg": [1, 2, 3, 4, 5], "gripper_deg": "open"}}', "'gripper_deg' that is not a finite number"),
    ],
)
def test_a_bad_file_is_moved_aside_reported_in_one_line_and_not_overwritten(tmp_path, content, problem):
    path = tmp_path / "poses.json"
    path.write_bytes(content)
    store = PoseStore(path)
    assert store.names() == []
    assert problem in store.load_notice
    assert "moved aside" in store.load_notice and "\n" not in store.load_notice
    aside = [name for name in os.listdir(tmp_path) if name.startswith("poses.json.corrupt-")]
    assert len(aside) == 1 and aside[0] in store.load_notice
    assert (tmp_path / aside[0]).read_bytes() == content

    assert store.save("new", Pose((0.0,) * 5)) is None
    assert list(json.loads(path.read_text())) == ["new"]
    assert (tmp_path / aside[0]).read_bytes() == content


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads and renames anything: permissions cannot make the file unreadable")
def test_an_unreadable_file_that_cannot_be_moved_is_left_alone(tmp_path):
    folder = tmp_path / "locked"
    folder.mkdir()
    path = folder / "poses.json"
    path.write_text('{"a": {"joints_deg": [1, 2, 3, 4, 5]}}')
    path.chmod(0)
    folder.chmod(0o500)  # no renames, no new files
    try:
        store = PoseStore(path)
        assert "cannot be read" in store.load_notice and "left as it is" in store.load_notice
        problem = store.save("b", Pose((0.0,) * 5))
        assert problem and "left untouched" in problem
        assert store.get("b") is not None  # kept for this run
    finally:
        folder.chmod(0o700)
        path.chmod(0o600)
    assert path.read_text() == '{"a": {"joints_deg": [1, 2, 3, 4, 5]}}'


def test_a_failed_write_is_reported_and_the_pose_kept_in_memory(tmp_path):
    path = tmp_path / "no_such_dir_is_a_file"
    path.write_text("")  # a file where the poses file's folder should be
    store = PoseStore(path / "poses.json")
    problem = store.save("a", Pose((0.0,) * 5))
    assert problem and str(path) in problem
    assert store.get("a") == Pose((0.0,) * 5)


SAVE_FOREVER = """
import sys
from so101.prompt.poses import Pose, PoseStore
store = PoseStore(sys.argv[1])
count = 0
while True:
    count += 1
    store.save(f"extra{count % 50}", Pose((float(count),) * 5))
    if count == 1:
        print("saving", flush=True)
"""


def test_a_prompt_killed_mid_save_leaves_the_file_whole(tmp_path):
    path = tmp_path / "poses.json"
    store = PoseStore(path)
    for index in range(500):  # a file of ~70 kB: each write takes long enough to be cut in the middle
        store.save(f"kept{index}", Pose((float(index),) * 5))
    chance = random.Random(101)
    for _ in range(10):
        saver = subprocess.Popen(
            [sys.executable, "-c", SAVE_FOREVER, str(path)], stdout=subprocess.PIPE, text=True,
            cwd=os.path.dirname(os.path.dirname(__file__)),
        )
        assert saver.stdout.readline() == "saving\n"
        time.sleep(chance.uniform(0.0, 0.03))
        saver.send_signal(signal.SIGKILL)
        saver.wait()
        reloaded = PoseStore(path)
        assert reloaded.load_notice is None
        assert {f"kept{index}" for index in range(500)} <= set(reloaded.names())
