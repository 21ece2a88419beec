"""`so101 bench --demos`: how fast `so101 demos` makes demonstrations, and where a frame's time goes.

Two parts. Throughput: `so101 demos` itself, as a user runs it (dora's start included), without
video and with both cameras, with one worker and with two: episodes a minute and simulated over
wall time. Where the time goes: the same work in this one process, an episode of the expert on
the body frame by frame as the lockstep body does, each stage timed alone: the physics (ten 4 ms
steps and the task's state), the expert, the two pictures, their encoding. What a frame costs in
the dataflow beyond the sum is dora's and the nodes' Python: two hops a frame (body to expert,
expert to body), with the runner beside them taking every message. Of that, dora's own part is
measured alone: the same messages between nodes that do nothing else (bench/nodes/echo_frames.py).
"""

from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from so101.runtime.lockstep import DEFAULT_LOCKSTEP_FPS

SO101 = Path(sys.executable).parent / "so101"
LAST_LINE = re.compile(r"demos: (\d+) episodes kept, (\d+) of (\d+) succeeded \(\d+%\), ([\d.]+) s, ([\d.]+)× real time")
SEED = 1000  # layouts the docs' scores do not use
TARGET_NO_VIDEO_X = 10.0  # the issue's: without video, one worker, at least 10× real time
TARGET_VIDEO_TWO_WORKERS_X = 2.0  # with both cameras at 320x240 and two workers, at least 2×


def run_demos(work_dir: Path, body: str, episodes: int, workers: int, image_size: tuple[int, int] | None) -> dict:
    """One `so101 demos` run into a new folder: its episodes a minute and its × real time."""
    name = f"{body}-{workers}-{'x'.join(map(str, image_size)) if image_size else 'no-video'}"
    video = ["--image-size", f"{image_size[0]}x{image_size[1]}"] if image_size else ["--no-video"]
    command = [str(SO101), "demos", str(work_dir / name), "--task", "cube_to_box", "--episodes", str(episodes),
               "--seed", str(SEED), "--body", body, "--workers", str(workers), "--lang", "en", *video]
    result = subprocess.run(command, capture_output=True, text=True, timeout=3600)
    match = LAST_LINE.search(result.stdout)
    if result.returncode != 0 or match is None:
        raise RuntimeError(f"so101 demos failed ({' '.join(command[1:])}): "
                           f"{(result.stderr.strip().splitlines() or ['no output'])[-1]}")
    wall_s, times = float(match.group(4)), float(match.group(5))
    ran = int(match.group(3))
    return {"episodes": ran, "succeeded": int(match.group(2)), "workers": workers,
            "image_size": list(image_size) if image_size else None, "wall_s": wall_s,
            "episodes_per_min": round(60 * ran / wall_s, 2), "times_real_time": times,
            "frames_per_s": round(times * DEFAULT_LOCKSTEP_FPS, 1)}


def stage_times(work_dir: Path, body: str, image_size: tuple[int, int], frames: int) -> dict:
    """Milliseconds per frame of each stage, in this process: an episode of the expert from seed SEED
    (its two videos encoded into `work_dir`, then removed)."""
    from so101.bodies.registry import BODIES
    from so101.bodies.task_cameras import TaskCameras
    from so101.dataset.stats import image_histogram
    from so101.dataset.video import StreamingEncoder
    from so101.runtime.lockstep import steps_per_frame
    from so101.tasks import CUBE_TO_BOX
    from so101.tasks.expert import Expert, planner_for

    # Drawn as the lockstep body draws them: by the one renderer of every body (so101.bodies.task_cameras).
    sim = BODIES[body].body_class()(mode="direct", time_step_s=0.004, renders=False,
                                    log=lambda line: None, task=CUBE_TO_BOX, seed=SEED)
    cameras = TaskCameras(CUBE_TO_BOX, log=lambda line: None)
    planner = planner_for(CUBE_TO_BOX)
    import so101.bodies.mujoco_model  # noqa: F401 (the expert's first plan imports it: once a run, as nodes/expert.py does at its start)
    expert = Expert(planner, seed=SEED)
    steps = steps_per_frame(DEFAULT_LOCKSTEP_FPS, 0.004)
    spent = {"physics": 0.0, "expert": 0.0, "pictures": 0.0, "encoding": 0.0}
    pictures: list[np.ndarray] = []
    try:
        for frame in range(frames):
            started = time.perf_counter()
            joints_deg, object_state = sim.joint_angles_deg(), sim.scene.object_state()
            sim.scene.succeeded()
            after_state = time.perf_counter()
            targets = expert.targets(frame / DEFAULT_LOCKSTEP_FPS, joints_deg, object_state)
            after_expert = time.perf_counter()
            sim.set_targets_deg(targets)
            sim.step(steps)
            after_step = time.perf_counter()
            pictures.extend(cameras.draw(sim.joint_angles_deg(), sim.scene.object_state(), *image_size))
            after_pictures = time.perf_counter()
            spent["physics"] += (after_state - started) + (after_step - after_expert)
            spent["expert"] += after_expert - after_state
            spent["pictures"] += after_pictures - after_step
    finally:
        sim.close()
        cameras.close()
        planner.close()
    encoders = [StreamingEncoder(work_dir / f"stages-{camera}.mp4", DEFAULT_LOCKSTEP_FPS, *image_size,
                                 inspect=image_histogram) for camera in range(2)]
    started = time.perf_counter()
    for index, picture in enumerate(pictures):
        encoders[index % 2].add(picture)
    for encoder in encoders:
        encoder.finish().path.unlink(missing_ok=True)
    spent["encoding"] = time.perf_counter() - started
    return {stage: round(1000 * seconds / frames, 2) for stage, seconds in spent.items()}


ECHO_NODE = Path(__file__).resolve().parent / "nodes" / "echo_frames.py"


def dora_alone_ms(work_dir: Path, frames: int) -> float:
    """Milliseconds a frame of the lockstep loop's messages takes with no work between them: the body's
    four outputs to a driver and a watcher, the driver's answer to both (bench/nodes/echo_frames.py),
    wired as so101/launch/lockstep.py wires them. The floor dora puts under a frame on this machine."""
    from so101.launch.lockstep import queued
    from so101.runtime.dataflow import write_dataflow
    from so101.runtime.venv import dora_executable, env_with_bin_first

    out = work_dir / "echo_ms.txt"
    state = ["joint_state", "gripper_state", "object_state"]
    nodes = [
        {"id": "body", "path": str(ECHO_NODE), "inputs": {"joint_cmd": queued("driver/joint_cmd")},
         "outputs": [*state, "task_status"], "env": {"ECHO_ROLE": "body", "ECHO_FRAMES": str(frames), "ECHO_OUT": str(out)}},
        {"id": "driver", "path": str(ECHO_NODE), "inputs": {name: queued(f"body/{name}") for name in state},
         "outputs": ["joint_cmd"], "env": {"ECHO_ROLE": "driver"}},
        {"id": "watcher", "path": str(ECHO_NODE), "env": {"ECHO_ROLE": "watcher"},
         "inputs": {**{name: queued(f"body/{name}") for name in [*state, "task_status"]}, "action": queued("driver/joint_cmd")}},
    ]
    dataflow = write_dataflow({"nodes": nodes}, work_dir / "echo.yml")
    subprocess.run([str(dora_executable()), "run", str(dataflow)], cwd=work_dir, env=env_with_bin_first(),
                   capture_output=True, timeout=300)
    return float(out.read_text())


def run_demos_benchmark(work_dir: Path, body: str, episodes: int, video_episodes: int,
                        image_size: tuple[int, int], stage_frames: int) -> dict:
    runs = {}
    for label, count, size in (("no_video", episodes, None), ("video", video_episodes, image_size)):
        for workers in (1, 2):
            runs[f"{label}_{workers}_workers"] = run_demos(work_dir, body, count, workers, size)
            print(f"  demos, {label.replace('_', ' ')}, {workers} worker(s): "
                  f"{runs[f'{label}_{workers}_workers']['times_real_time']}× real time", flush=True)
    stages = stage_times(work_dir, body, image_size, stage_frames)
    in_dataflow_ms = 1000 / runs["no_video_1_workers"]["frames_per_s"]
    stages["dora_and_the_rest_without_video"] = round(in_dataflow_ms - stages["physics"] - stages["expert"], 2)
    stages["dora_alone"] = round(dora_alone_ms(work_dir, 300 if stage_frames < 100 else 3000), 2)
    return {"runs": runs, "ms_per_frame": stages, "image_size": list(image_size)}


def table_lines(figures: dict) -> list[str]:
    size = "x".join(map(str, figures["image_size"]))
    lines = [f"{'so101 demos (episodes/min | × real time)':<40}"]
    for key, run in figures["runs"].items():
        what = "no video" if run["image_size"] is None else f"two cameras {size}"
        label = f"{what}, {run['workers']} worker{'s' if run['workers'] > 1 else ''}"
        lines.append(f"{label:<40} {run['episodes_per_min']:>8.1f} | {run['times_real_time']:<6.1f} "
                     f"({run['episodes']} episodes, {run['wall_s']:.0f} s)")
    stages = figures["ms_per_frame"]
    lines.append("a frame's time, in one process (ms per frame):")
    names = {"physics": "physics (ten 4 ms steps, the task's state)", "expert": "the expert",
             "pictures": f"two pictures, {size}", "encoding": "their encoding (AV1, and the image statistics)",
             "dora_and_the_rest_without_video": "dora and the rest: a frame in the dataflow, less the above",
             "dora_alone": "of which dora alone: a frame's messages between empty nodes"}
    for stage, name in names.items():
        if stage not in stages:  # a result saved before the row was measured
            continue
        lines.append(f"  {name:<62} {stages[stage]:>8.2f}")
    return lines


def targets(figures: dict, joint_state_target: float, sim_error_target: float) -> list[dict]:
    from bench.common import target_row

    runs = figures["runs"]
    no_video, video = runs["no_video_1_workers"]["times_real_time"], runs["video_2_workers"]["times_real_time"]
    return [
        target_row("demos without video, 1 worker: × real time", no_video, f">= {TARGET_NO_VIDEO_X:g}",
                   no_video >= TARGET_NO_VIDEO_X),
        target_row("demos with both cameras, 2 workers: × real time", video, f">= {TARGET_VIDEO_TWO_WORKERS_X:g}",
                   video >= TARGET_VIDEO_TWO_WORKERS_X),
    ]
