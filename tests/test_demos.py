"""`so101 demos` and `so101 eval` as a user runs them: lockstep dataflows of a body, the expert and the
episodes' runner. The same seeds give the same episodes, bit for bit, on both simulators; an idle arm
scores 0; what is written is a dataset that reads, and appends; bad input is one line."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from so101.bodies.registry import SIMULATED_BODIES
from so101.dataset.features import ACTION_KEY, ENVIRONMENT_KEY, STATE_KEY, SUCCESS_KEY, WRIST_IMAGE_KEY
from so101.dataset.layout import SEEDS_KEY
from so101.dataset.reader import Dataset
from so101.dataset.writer import DatasetWriter

pytestmark = pytest.mark.dataflow

SO101 = Path(sys.executable).parent / "so101"
EPISODE_LINE = re.compile(r"^episode (\d+) \(seed (\d+)\): (success in [\d.]+ s|failed \(time limit, [\d.]+ s\)), "
                          r"(\d+) frames(, kept)?$")


def so101(*args, timeout=300):
    return subprocess.run([str(SO101), *args, "--lang", "en"], capture_output=True, text=True, timeout=timeout)


def episode_lines(stdout: str) -> list[str]:
    return [line for line in stdout.splitlines() if EPISODE_LINE.match(line)]


def frames_of(root: Path) -> dict[str, np.ndarray]:
    dataset = Dataset.open(root)
    keys = (STATE_KEY, ACTION_KEY, ENVIRONMENT_KEY, SUCCESS_KEY)
    episodes = [dataset.episode_frames(index) for index in range(len(dataset.episodes))]
    return {key: np.concatenate([np.asarray(frames[key]) for frames in episodes]) for key in keys}


@pytest.mark.parametrize("body", SIMULATED_BODIES)
def test_the_same_seeds_make_the_same_demonstrations_bit_for_bit(tmp_path, body):
    runs = []
    for name in ("first", "second"):
        result = so101("demos", str(tmp_path / name), "--task", "cube_to_box", "--episodes", "2", "--seed", "5",
                       "--body", body, "--no-video", "--noise", "1")
        assert result.returncode == 0, result.stdout + result.stderr
        runs.append(result.stdout)
    lines = episode_lines(runs[0])
    assert [EPISODE_LINE.match(line).group(2) for line in lines] == ["5", "6"]
    assert all(line.endswith(", kept") and "success in" in line for line in lines), runs[0]
    assert episode_lines(runs[1]) == lines
    last = runs[0].splitlines()[-1]
    assert re.fullmatch(r"demos: 2 episodes kept, 2 of 2 succeeded \(100%\), [\d.]+ s, [\d.]+× real time", last), last
    first, second = frames_of(tmp_path / "first"), frames_of(tmp_path / "second")
    for key in first:
        assert np.array_equal(first[key], second[key]), key
    # The cube moved (the expert did the task) and the last frame of each episode is a success.
    assert np.ptp(first[ENVIRONMENT_KEY][:, 2]) > 0.05
    dataset = Dataset.open(tmp_path / "first")
    assert dataset.fps == 25 and [episode.tasks for episode in dataset.episodes] == [("put the cube in the box",)] * 2
    assert all(bool(dataset.episode_frames(index)[SUCCESS_KEY][-1]) for index in range(2))
    assert dataset.info[SEEDS_KEY] == {"0": 5, "1": 6}
    assert dataset.info["so101_episode_scenarios"] == {"0": {"physics": {"physics": "fixed"}},
                                                       "1": {"physics": {"physics": "fixed"}}}


def test_with_misses_an_episode_is_written_from_the_recovery_on(tmp_path):
    result = so101("demos", str(tmp_path / "misses"), "--task", "cube_to_box", "--episodes", "2", "--seed", "300",
                   "--no-video", "--misses", "1")
    assert result.returncode == 0, result.stdout + result.stderr
    played = [int(EPISODE_LINE.match(line).group(4)) for line in episode_lines(result.stdout)]
    assert len(played) == 2 and all(line.endswith(", kept") for line in episode_lines(result.stdout)), result.stdout
    dataset = Dataset.open(tmp_path / "misses")
    for index, frames_played in enumerate(played):
        frames = dataset.episode_frames(index)
        written = len(frames[STATE_KEY])
        assert 100 < written < frames_played - 100  # the approach, the miss and the lift (6 s or more) are not written
        first_state, cube_xyz = np.asarray(frames[STATE_KEY][0]), np.asarray(frames[ENVIRONMENT_KEY][0])[:3]
        # It starts with the arm up from the miss, its jaws shut on nothing, the cube still on the floor.
        assert np.abs(first_state[:5]).max() > 10.0 and first_state[5] < 15.0, first_state
        assert abs(cube_xyz[2] - 0.0125) < 0.002, cube_xyz
        assert bool(frames[SUCCESS_KEY][-1])


def test_eval_scores_the_expert_and_an_idle_arm_scores_nothing(tmp_path):
    expert = so101("eval", "--expert", "--task", "cube_to_box", "--episodes", "3", "--seed", "20")
    assert expert.returncode == 0, expert.stdout + expert.stderr
    assert len(episode_lines(expert.stdout)) == 3
    assert re.fullmatch(r"success: 3/3 \(100%, 95% CI 44–100%, Wilson\), mean time to success [\d.]+ s",
                        expert.stdout.splitlines()[-1]), expert.stdout
    # Two workers (seeds 20 and 21, then 22): the same lines, in seed order, and the same score.
    workers = so101("eval", "--expert", "--task", "cube_to_box", "--episodes", "3", "--seed", "20", "--workers", "2")
    assert workers.returncode == 0, workers.stdout + workers.stderr
    assert episode_lines(workers.stdout) == episode_lines(expert.stdout)
    assert workers.stdout.splitlines()[-1] == expert.stdout.splitlines()[-1]
    idle = so101("eval", "--idle", "--task", "cube_to_box", "--episodes", "2", "--time-limit", "2", "--body", "mujoco")
    assert idle.returncode == 0, idle.stdout + idle.stderr
    assert episode_lines(idle.stdout) == ["episode 0 (seed 0): failed (time limit, 2.0 s), 51 frames",
                                          "episode 1 (seed 1): failed (time limit, 2.0 s), 51 frames"]
    assert idle.stdout.splitlines()[-1] == "success: 0/2 (0%, 95% CI 0–66%, Wilson), mean time to success none (no success)"


def test_demos_with_video_append_to_the_folder_and_every_episode_reads(tmp_path):
    from dataclasses import replace

    from so101.bodies.camera_file import default_camera_file, read_camera_file
    from so101.bodies.scenario import Scenario
    from so101.dataset.layout import SCENARIOS_KEY

    root = tmp_path / "demos"
    moved = tmp_path / "front.json"  # the front camera 3 cm to the left of the simulator's, 4° wider
    default = default_camera_file("front")
    moved.write_text(replace(default, position_m=(default.position_m[0], default.position_m[1] + 0.03,
                                                  default.position_m[2]), fov_deg=49.0).as_json(), encoding="utf-8")
    for seed, looks in (("0", "fixed"), ("1", "varied")):  # --image-size is --camera-size's older name
        result = so101("demos", str(root), "--task", "cube_to_box", "--episodes", "1", "--seed", seed,
                       "--camera-size" if looks == "varied" else "--image-size", "160x120", "--looks", looks,
                       *(["--camera-pose", f"front={moved}"] if looks == "varied" else []))
        assert result.returncode == 0, result.stdout + result.stderr
    dataset = Dataset.open(root)
    assert len(dataset.episodes) == 2
    # A dataset says what its pictures showed, by episode, and where its cameras stood: its scenario, as drawn.
    assert dataset.info[SCENARIOS_KEY] == {
        "0": Scenario().metadata(0, ("front", "wrist"), (160, 120)),
        "1": Scenario("varied", {"front": read_camera_file(moved)}).metadata(1, ("front", "wrist"), (160, 120))}
    assert dataset.info[SCENARIOS_KEY]["1"]["looks"]["looks"] == "varied"
    assert dataset.info[SCENARIOS_KEY]["0"]["cameras"]["front"]["position_m"] == [round(v, 6) for v in default.position_m]
    for index in range(2):
        frames = dataset.episode_frames(index)
        front = list(dataset.episode_images(index, "observation.images.front"))
        wrist = list(dataset.episode_images(index, "observation.images.wrist"))
        assert len(front) == len(wrist) == len(frames[STATE_KEY])
        assert front[0].shape == (120, 160, 3)
        assert np.abs(front[-1].astype(int) - front[0].astype(int)).mean() > 1.0  # the arm and the cube moved
    # --observe: frames for a policy that sees what a real arm would, without the simulator's object poses.
    seen = tmp_path / "seen"
    result = so101("demos", str(seen), "--task", "cube_to_box", "--episodes", "1", "--camera-size", "96x72",
                   "--observe", "state,wrist")
    assert result.returncode == 0, result.stdout + result.stderr
    assert "observing state,wrist (wrist 96x72)" in result.stdout.splitlines()[0]
    dataset = Dataset.open(seen)
    assert [key for key in dataset.info["features"] if key.startswith("observation")] == [STATE_KEY, WRIST_IMAGE_KEY]
    assert len(list(dataset.episode_images(0, WRIST_IMAGE_KEY))) == len(dataset.episode_frames(0)[STATE_KEY])


def test_two_workers_write_the_dataset_one_worker_writes_byte_for_byte(tmp_path):
    outputs = {}
    for workers in ("1", "2"):  # two workers: seeds 30 and 31, then 32
        result = so101("demos", str(tmp_path / workers), "--task", "cube_to_box", "--episodes", "3", "--seed", "30",
                       "--body", "mujoco", "--noise", "1", "--image-size", "64x48", "--workers", workers,
                       "--keep", "all", "--time-limit", "12", "--looks", "varied", "--physics", "varied")
        assert result.returncode == 0, result.stdout + result.stderr
        outputs[workers] = result.stdout
    assert episode_lines(outputs["2"]) == episode_lines(outputs["1"])
    assert [EPISODE_LINE.match(line).group(2) for line in episode_lines(outputs["2"])] == ["30", "31", "32"]
    files = {workers: sorted(path.relative_to(tmp_path / workers) for path in (tmp_path / workers).rglob("*")
                             if path.is_file()) for workers in outputs}
    assert files["2"] == files["1"] and Path("videos/observation.images.wrist/chunk-000/file-000.mp4") in files["1"]
    for name in files["1"]:
        assert (tmp_path / "2" / name).read_bytes() == (tmp_path / "1" / name).read_bytes(), name
    merged = Dataset.open(tmp_path / "2")
    assert len(merged.episodes) == 3
    # Each worker's episodes keep their looks and physics through the merge: seeds 30, 31, 32 in episode order.
    from so101.bodies.physics import physics_metadata
    from so101.dataset.layout import SCENARIOS_KEY

    kept = merged.info[SCENARIOS_KEY]
    assert [kept[str(index)]["looks"]["seed"] for index in range(3)] == [30, 31, 32]
    assert [kept[str(index)]["physics"] for index in range(3)] == [physics_metadata("varied", seed) for seed in (30, 31, 32)]


def test_on_a_cluster_the_workers_spread_over_its_machines_and_the_dataset_is_the_same(tmp_path):
    from so101.runtime.cluster import Cluster

    with Cluster(tmp_path / "cluster") as cluster:  # a coordinator with a token, daemons `arm` and `desk`
        cluster.start_coordinator()
        cluster.start_daemon("arm")
        cluster.start_daemon("desk")
        spread = subprocess.run(
            [str(SO101), "demos", str(tmp_path / "spread"), "--task", "cube_to_box", "--episodes", "3", "--seed", "40",
             "--no-video", "--workers", "2", "--coordinator", f"127.0.0.1:{cluster.coordinator_port}",
             "--machine", "desk", "--lang", "en"],
            capture_output=True, text=True, timeout=300, env=dict(os.environ, DORA_AUTH_TOKEN=cluster.token))
        assert spread.returncode == 0, spread.stdout + spread.stderr
        assert "demos: worker 0 (seeds 40..41) on machine 'arm'" in spread.stdout
        assert "demos: worker 1 (seeds 42..42) on machine 'desk'" in spread.stdout
        # Each daemon ran a body; the runners ran on `desk`, this machine's daemon, where the dataset is written.
        assert cluster.node_log("arm", "simulation") and cluster.node_log("desk", "simulation")
        assert not cluster.node_log("arm", "episodes") and cluster.node_log("desk", "episodes")
        refused = subprocess.run(
            [str(SO101), "eval", "--expert", "--task", "cube_to_box", "--coordinator",
             f"127.0.0.1:{cluster.coordinator_port}", "--machine", "laptop", "--lang", "en"],
            capture_output=True, text=True, timeout=60, env=dict(os.environ, DORA_AUTH_TOKEN=cluster.token))
        assert refused.returncode == 1 and refused.stderr.strip().startswith(
            "so101 eval: no daemon with machine id 'laptop' on the coordinator at 127.0.0.1:"), refused.stderr
        assert "(its daemons: arm, desk;" in refused.stderr
    here = so101("demos", str(tmp_path / "here"), "--task", "cube_to_box", "--episodes", "3", "--seed", "40", "--no-video")
    assert here.returncode == 0, here.stdout + here.stderr
    assert episode_lines(spread.stdout) == episode_lines(here.stdout)
    for name in ("data/chunk-000/file-000.parquet", "meta/episodes/chunk-000/file-000.parquet", "meta/info.json",
                 "meta/stats.json"):
        assert (tmp_path / "spread" / name).read_bytes() == (tmp_path / "here" / name).read_bytes(), name


@pytest.mark.parametrize("workers", ["1", "2"])
def test_demos_stopped_part_way_keep_whole_episodes_and_a_rerun_appends(tmp_path, workers):
    root = tmp_path / "demos"
    process = subprocess.Popen([str(SO101), "demos", str(root), "--task", "cube_to_box", "--episodes", "8", "--seed", "0",
                                "--no-video", "--workers", workers, "--lang", "en"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        for line in process.stdout:
            if line.startswith("episode 0 "):
                break
        process.send_signal(signal.SIGTERM)  # `kill`, mid-way through the second episode or later
        out, err = process.communicate(timeout=60)
    finally:
        process.kill()
    assert process.returncode == 1, out + err
    stopped = re.fullmatch(r"so101 demos: stopped \(Ctrl-C, or a signal\): the episode running was dropped "
                           r"\((\d+) episodes were kept before it\)", err.strip().splitlines()[-1])
    assert stopped, err
    kept = int(stopped.group(1))
    assert 1 <= kept < 8 and len(Dataset.open(root).episodes) == kept
    # The dataflow stopped with it (a second one could not start while it ran), and a rerun appends.
    again = so101("demos", str(root), "--task", "cube_to_box", "--episodes", "2", "--seed", "8", "--no-video",
                  "--workers", workers)
    assert again.returncode == 0, again.stdout + again.stderr
    dataset = Dataset.open(root)
    assert len(dataset.episodes) == kept + 2
    for index in range(kept + 2):
        frames = dataset.episode_frames(index)
        assert len(frames[STATE_KEY]) == dataset.episodes[index].length and bool(frames[SUCCESS_KEY][-1])
    assert dataset.info[SEEDS_KEY] == {str(index): index for index in range(kept)} | {str(kept): 8, str(kept + 1): 9}


@pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux is not installed (.ci/run installs it)")
def test_at_the_prompt_the_expert_does_the_task_and_a_typed_command_takes_over(tmp_path):
    from tests.helpers.terminal import start_teleop

    terminal, _, _ = start_teleop(tmp_path, "en", extra="--task cube_to_box --seed 3")
    try:
        terminal.seen = terminal.wait_for_prompt(timeout_s=120).start()
        terminal.command("expert", re.escape("  → the expert is doing the task; any move you type takes over"))
        # Paced by the wall clock: about 9 s for the task, then home.
        terminal.wait_for(re.escape("  ★ the cube is in the box (task cube_to_box, seed 3)"), timeout_s=60,
                          after=terminal.seen)
        done = terminal.wait_for(r"^  \[expert\] done: ([\d.]+) s, 1 grasp\(s\)$", timeout_s=30, after=terminal.seen)
        assert 8.0 < float(done.group(1)) < 20.0
        terminal.seen = done.end()
        terminal.command("task", r"  task cube_to_box, seed 3: .*\n  the cube is now at .*: in the box")
        terminal.command("reset", r"  → laid out from seed 4, the arm at home: .*")
        terminal.command("expert", re.escape("  → the expert is doing the task; any move you type takes over"))
        time.sleep(2.0)
        terminal.command("0 40", re.escape("  → joint 0 (shoulder_pan) → 40°"))
        terminal.wait_for(re.escape("  [expert] a typed command took over: the expert stopped"), timeout_s=10,
                          after=terminal.seen)
        time.sleep(3.0)  # the expert sends nothing more: the arm stays where it was typed to
        pan_deg = float(terminal.command("state", r"  joint angles now: \[(-?[\d.]+),.*").group(1))
        assert abs(pan_deg - 40.0) < 2.0
        terminal.type_line("quit")
        terminal.wait_for(r"^TELEOP_EXIT=0$", timeout_s=60, after=terminal.seen)
    finally:
        terminal.close()


@pytest.mark.skipif(os.geteuid() != 0 or shutil.which("unshare") is None,
                    reason="a small filesystem of its own needs root (unshare --mount, mount -t tmpfs)")
def test_a_full_disk_stops_demos_in_one_line_and_the_saved_episodes_stay_whole(tmp_path):
    small = tmp_path / "small"  # 1 MB, with room for a few episodes: a tmpfs in a mount namespace of its own
    small.mkdir()
    demos = f"{SO101} demos {small}/demos --task cube_to_box --no-video --lang en"
    script = f"""
        mount -t tmpfs -o size=1m tmpfs {small}
        head -c 760k /dev/zero > {small}/filler
        {demos} --episodes 20 > {tmp_path}/full.out 2>&1; echo $? > {tmp_path}/full.code
        cp -r {small}/demos {tmp_path}/at-full
        rm {small}/filler
        {demos} --episodes 1 --seed 20 > {tmp_path}/again.out 2>&1; echo $? > {tmp_path}/again.code
        cp -r {small}/demos {tmp_path}/again
    """
    subprocess.run(["unshare", "--mount", "--propagation", "private", "bash", "-c", script], timeout=600, check=True)
    full = (tmp_path / "full.out").read_text()
    assert (tmp_path / "full.code").read_text().strip() == "1", full
    stopped = re.fullmatch(r"so101 demos: \[episodes\] cannot go on: episode (\d+) is not saved: No space left on device; "
                           r"the dataset in .* is as it was \(seed \1\) \((\d+) episodes were kept before it\)",
                           full.strip().splitlines()[-1])
    assert stopped and stopped.group(1) == stopped.group(2) != "0", full
    kept = int(stopped.group(2))
    assert len(Dataset.open(tmp_path / "at-full").episodes) == kept
    assert (tmp_path / "again.code").read_text().strip() == "0", (tmp_path / "again.out").read_text()
    dataset = Dataset.open(tmp_path / "again")
    assert len(dataset.episodes) == kept + 1 and dataset.info[SEEDS_KEY][str(kept)] == 20
    for index in range(kept + 1):
        assert bool(dataset.episode_frames(index)[SUCCESS_KEY][-1])


@pytest.mark.parametrize("args, message", [
    (["eval", "--expert", "--task", "cube_to_box", "--body", "real"], "the real arm has no object state"),
    (["demos", "DIR", "--task", "cube_to_box", "--body", "real"], "the real arm has no object state"),
    (["eval", "--expert", "--task", "stack_cubes"], "invalid choice: 'stack_cubes'"),
    (["eval", "--expert", "--task", "cube_to_box", "--episodes", "0"], "'0' is not a whole number from 1"),
    (["eval", "--task", "cube_to_box"], "one of the arguments --expert --idle --policy is required"),
    (["demos", "DIR", "--task", "cube_to_box", "--workers", "0"], "'0' is not a whole number from 1 to 16"),
    (["demos", "DIR", "--task", "cube_to_box", "--misses", "2"], "'2' is not a share from 0 to 1"),
    (["eval", "--idle", "--task", "cube_to_box", "--misses", "0.5"], "--noise and --misses are the scripted expert's"),
    (["demos", "DIR", "--task", "cube_to_box", "--machine", "desk"], "--machine and --root go with --coordinator"),
    (["eval", "--expert", "--task", "cube_to_box", "--coordinator", "10.0.0.1"], "--coordinator needs --machine ID"),
    (["eval", "--idle", "--task", "cube_to_box", "--coordinator", "10.0.0.1:port", "--machine", "desk"],
     "--coordinator '10.0.0.1:port' is not ADDR[:PORT]"),
    (["demos", "OTHER", "--task", "cube_to_box", "--no-video"], "fps"),
    (["demos", "DIR", "--task", "cube_to_box", "--observe", "front,wrist"], "state is always shown (the arm's joints)"),
    (["demos", "DIR", "--task", "cube_to_box", "--observe", "state,cube"], "'cube' is not something the frames can show"),
    (["demos", "DIR", "--task", "cube_to_box", "--no-video", "--observe", "state,front"],
     "--observe state,front: front and wrist are the cameras, and there are none here (--no-video)"),
    (["eval", "--expert", "--task", "cube_to_box", "--physics", "heavy"],
     "argument --physics: unknown physics 'heavy'; use fixed, varied, or a JSON file of ranges"),
    (["demos", "DIR", "--task", "cube_to_box", "--physics", "/no/ranges.json"],
     "argument --physics: cannot read physics ranges /no/ranges.json"),
    (["demos", "DIR", "--task", "cube_to_box", "--takeover-s", "5"], "--takeover-s goes with --learner DIR"),
    (["demos", "DIR", "--task", "cube_to_box", "--learner", "/no/policy"], "--learner: /no/policy is not a folder"),
])
def test_bad_input_is_one_line_and_starts_nothing(tmp_path, args, message):
    other = tmp_path / "other"
    with DatasetWriter.open(other, 30, {}):  # a recording at 30 fps, of no task
        pass
    args = [str(tmp_path / "new") if arg == "DIR" else str(other) if arg == "OTHER" else arg for arg in args]
    result = so101(*args, timeout=60)
    assert result.returncode != 0
    last = result.stderr.strip().splitlines()[-1]  # argparse's usage may come before it
    assert last.startswith(f"so101 {args[0]}") and message in last, result.stderr
    assert "Traceback" not in result.stderr
