"""Recording's cost to the body (issue 20): `so101 bench` runs these for a simulated body.

  1. a picture of the arm (320x240, as the node draws it: so101.bodies.task_cameras), ms: what drawing it inside the
     physics loop would cost each time;
  2. the body drawing its pictures inside its loop at 30 Hz (SO101_IMAGE_HZ=30): joint_state/s and
     simulated/wall time, measured, not assumed;
  3. the dataflow of `so101 teleop --record`: the camera node drawing, the recorder taking an
     episode with video for the whole run: joint_state/s, simulated/wall time, the frames kept per
     second and how many distinct pictures they hold;
  4. saving a 60 s episode (1800 frames with video) in process: add_frame per frame, and save().
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path
from typing import Callable

import numpy as np

from bench.common import PACED_PROBE_ENV, WARMUP_S, run_dataflow, realtime_figures
from so101.bodies.task_cameras import IMAGE_SIZE, TaskCameras
from so101.bodies.registry import BODIES
from so101.dataset.features import ACTION_KEY, DEFAULT_FPS, IMAGE_KEY, STATE_KEY, to_lerobot
from so101.dataset.video import new_while_moving, picture_changes
from so101.runtime.dataflow import TICK_PERIOD_S, with_recorder, with_task
from so101.stats import summary

SAVED_EPISODE_S = 60.0
RECORD_AT_STATE = 250  # bench/nodes/prober.py's: when it sends `record`
# Two decoded frames differing by more than this mean, in 0-255 levels, hold different pictures: a picture
# repeated (a camera that fell behind) decodes the same to the level, and the task's cameras' pictures of
# an arm moved half a degree differ by 0.86 and more (tests/test_task_cameras.py). 1.0, used before,
# counted a third of the wrist's new pictures as repeats.
NEW_PICTURE_LEVELS = 0.05
PICTURES = 20  # the in-process picture timing, and the distinct poses of the saved episode


def measure_picture_ms(body: str) -> dict:
    """Pictures of the arm at IMAGE_SIZE, drawn as `body`'s node draws its `image` output (by the one
    renderer of every body, so101.bodies.task_cameras), ms each."""
    with TaskCameras(None, log=lambda message: None) as cameras:
        cameras.draw([0.0] * 6, [], *IMAGE_SIZE)
        each_ms = []
        for index in range(PICTURES):
            start = time.perf_counter()
            cameras.draw([3.0 * index, -2.0 * index, 2.0 * index, 0, 4.0 * index, 10], [], *IMAGE_SIZE)
            each_ms.append((time.perf_counter() - start) * 1e3)
    return summary(each_ms)


def measure_in_loop(run_dir: Path, duration_s: float, body: str) -> dict:
    """The body draws a picture every 1/30 s inside its own loop."""
    record = run_dataflow(run_dir, duration_s + WARMUP_S, {"SO101_FAST_STEPS": "0", "SO101_IMAGE_HZ": str(DEFAULT_FPS)},
                          PACED_PROBE_ENV, body=body)
    flow = realtime_figures(record, TICK_PERIOD_S)["dataflow"]
    return {"joint_state_per_s": flow["joint_state_per_s"], "sim_over_wall": flow["sim_over_wall"],
            "ticks_missed": flow["ticks_missed"]}


def record_run(run_dir: Path, duration_s: float, body: str, image_size: tuple[int, int] = IMAGE_SIZE,
               task: str | None = None, during: Callable[[float], None] | None = None) -> tuple[dict, dict]:
    """`so101 teleop --record`'s dataflow (with `task`: `--task`'s) while the prober moves the arm, an
    episode with video recorded throughout: (the dataflow's real-time figures, the episode's:
    frames, seconds recorded and wall-clock seconds, and each video's new pictures a second).
    `during`: as run_dataflow's."""
    from so101.dataset.reader import Dataset

    dataset_dir = run_dir / "dataset"
    size = f"{image_size[0]}x{image_size[1]}"
    node_id = BODIES[body].node_id

    def add_recorder(descriptor: dict) -> None:
        if task is not None:
            with_task(descriptor, node_id, task, 0)
        with_recorder(descriptor, node_id,
                      {"SO101_RECORD_DIR": str(dataset_dir), "SO101_RECORD_FPS": str(DEFAULT_FPS),
                       "SO101_RECORD_IMAGE_SIZE": size, "SO101_LANG": "en"},
                      {"SO101_RECORD_IMAGE_SIZE": size}, picture_hz=DEFAULT_FPS)

    record = run_dataflow(run_dir, duration_s + WARMUP_S, {"SO101_FAST_STEPS": "0"},
                          {**PACED_PROBE_ENV, "PROBE_RECORD_TASK": "so101 bench"}, body=body, extend=add_recorder,
                          during=during)
    flow = realtime_figures(record, TICK_PERIOD_S)["dataflow"]
    states = record["probe"]["states"]
    # The episode starts at the prober's RECORD_AT_STATE-th state and ends at STOP, just after the last.
    episode_wall_s = (states[-1][0] - states[min(RECORD_AT_STATE, len(states)) - 1][0]) / 1e9
    dataset = Dataset.open(dataset_dir)
    if not dataset.episodes:
        raise RuntimeError(f"the recorder saved no episode (see {run_dir / 'dora.log'})")
    episode = dataset.episodes[-1]
    recorded_s = episode.length / dataset.fps
    changes = {key: picture_changes(dataset.episode_images(episode.index, key), NEW_PICTURE_LEVELS)
               for key in dataset.video_keys}
    states = dataset.episode_frames(episode.index)[STATE_KEY]
    return flow, {"frames": episode.length, "recorded_s": recorded_s, "wall_s": episode_wall_s,
                  "new_pictures_per_s": {key: sum(changed) / recorded_s if recorded_s else 0.0
                                         for key, changed in changes.items()},
                  # The share of the frames in which the arm moved that hold a new picture.
                  "new_while_moving": {key: new_while_moving(changed, states) for key, changed in changes.items()}}


def measure_recording(run_dir: Path, duration_s: float, body: str) -> dict:
    """The body, the camera and the recorder, an episode with video recorded throughout."""
    flow, episode = record_run(run_dir, duration_s, body)
    return {"joint_state_per_s": flow["joint_state_per_s"], "sim_over_wall": flow["sim_over_wall"],
            "ticks_missed": flow["ticks_missed"], "frames": episode["frames"], "recorded_s": episode["recorded_s"],
            "frames_per_wall_s": episode["frames"] / episode["wall_s"] if episode["wall_s"] > 0 else 0.0,
            "new_pictures_per_s": episode["new_pictures_per_s"][IMAGE_KEY]}


def measure_saving(body: str, seconds: float = SAVED_EPISODE_S) -> dict:
    """A `seconds` episode at 30 fps with video, frames added as the recorder adds them, then saved."""
    from so101.dataset.writer import DatasetWriter

    with TaskCameras(None, log=lambda message: None) as cameras:
        poses = [[40 * np.sin(index / 3), -20 + index, 30 - 2 * index, 10, 5 * index, 20 + 3 * index]
                 for index in range(PICTURES)]
        pictures = [cameras.draw(pose, [], *IMAGE_SIZE)[0] for pose in poses]
    work = Path(tempfile.mkdtemp(prefix="so101-bench-save-"))
    try:
        writer = DatasetWriter.open(work / "dataset", DEFAULT_FPS, {IMAGE_KEY: IMAGE_SIZE})
        episode = writer.start_episode("so101 bench")
        frames = round(seconds * DEFAULT_FPS)
        add_ms = []
        for index in range(frames):
            pose = poses[(index // 3) % PICTURES]  # a new picture every 3 frames, as the camera's rate gives
            start = time.perf_counter()
            episode.add_frame({STATE_KEY: to_lerobot(pose), ACTION_KEY: to_lerobot(pose),
                               IMAGE_KEY: pictures[(index // 3) % PICTURES]})
            add_ms.append((time.perf_counter() - start) * 1e3)
        start = time.perf_counter()
        episode.save()
        save_s = time.perf_counter() - start
        writer.close()
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return {"episode_s": seconds, "frames": frames, "save_s": save_s, "add_frame_ms": summary(add_ms)}


def run_recording_benchmark(work_dir: Path, duration_s: float, body: str, saved_episode_s: float = SAVED_EPISODE_S) -> dict:
    print(f"recording: a picture's cost, {PICTURES} pictures ...", flush=True)
    figures = {"picture_ms": measure_picture_ms(body)}
    print(f"recording: pictures drawn inside the physics loop at {DEFAULT_FPS} Hz, {duration_s:g} s ...", flush=True)
    figures["pictures_in_loop"] = measure_in_loop(work_dir / "in_loop", duration_s, body)
    print(f"recording: so101 teleop --record's dataflow with video, {duration_s:g} s ...", flush=True)
    figures["recording"] = measure_recording(work_dir / "recording", duration_s, body)
    print(f"recording: saving a {saved_episode_s:g} s episode ...", flush=True)
    figures["saving"] = measure_saving(body, saved_episode_s)
    return figures


def table_lines(figures: dict) -> list[str]:
    picture, in_loop, recording, saving = (figures[key] for key in ("picture_ms", "pictures_in_loop", "recording", "saving"))
    return [
        f"{'a picture, ' + 'x'.join(map(str, IMAGE_SIZE)) + ' (ms, p50 | p99)':<52} {picture['p50']:>10.1f} | {picture['p99']:<9.1f}",
        f"{'pictures inside the loop at 30 Hz: joint_state per s':<52} {in_loop['joint_state_per_s']:>10.2f}",
        f"{'  simulated / wall time':<52} {in_loop['sim_over_wall']:>10.4f}",
        f"{'recording with video: joint_state per s':<52} {recording['joint_state_per_s']:>10.2f}",
        f"{'  simulated / wall time':<52} {recording['sim_over_wall']:>10.4f}",
        f"{'  frames per wall-clock s (30 expected) | new pictures':<52} "
        f"{recording['frames_per_wall_s']:>10.2f} | {recording['new_pictures_per_s']:<9.2f}",
        f"{'saving a ' + format(saving['episode_s'], 'g') + ' s episode with video (s)':<52} {saving['save_s']:>10.2f}",
        f"{'  add_frame, with video encoding (ms, p50 | p99)':<52} {saving['add_frame_ms']['p50']:>10.2f} | {saving['add_frame_ms']['p99']:<9.2f}",
    ]
