"""A task's cameras (issue "Something to pick up"): `so101 bench --cameras` runs these for a simulated body.

  1. pictures alone: the camera node's simulator (the task's scene, MuJoCo's pictures light) draws
     the front and the wrist camera at 320x240 (or --image-size) in turn, nothing else running: ms a picture, and
     so the pictures a second each camera could give;
  2. beside the physics: `so101 teleop --task cube_to_box --record`'s dataflow (the body, the
     camera node, the recorder with both videos) while the prober moves the arm: the body's
     joint_state/s and simulated/wall time, and the new pictures a second each video holds.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from bench.record_bench import record_run
from so101.bodies.camera import WRIST_CAMERA
from so101.bodies.node_loop import IMAGE_SIZE
from so101.bodies.registry import BODIES
from so101.dataset.features import DEFAULT_FPS, IMAGE_KEY, WRIST_IMAGE_KEY
from so101.runtime.dataflow import TICK_PERIOD_S
from so101.stats import summary
from so101.tasks import CUBE_TO_BOX

PICTURES = 20  # poses drawn by each camera in the in-process timing
CAMERAS = {IMAGE_KEY: None, WRIST_IMAGE_KEY: WRIST_CAMERA}  # None: the body's default (front) camera


def measure_pictures_alone(body: str, image_size: tuple[int, int]) -> dict:
    """Each camera's pictures of the task's scene, drawn as the camera node draws them, ms each."""
    with BODIES[body].body_class()(mode="direct", time_step_s=TICK_PERIOD_S, log=lambda message: None,
                                   task=CUBE_TO_BOX, light_pictures=True) as sim:
        figures = {}
        for key, camera in CAMERAS.items():
            options = {} if camera is None else {"camera": camera}
            sim.render_rgb(*image_size, **options)
            each_ms = []
            for index in range(PICTURES):
                sim.show_pose_deg([3.0 * index, -2.0 * index, 2.0 * index, 10, 4.0 * index, 30])
                start = time.perf_counter()
                sim.render_rgb(*image_size, **options)
                each_ms.append((time.perf_counter() - start) * 1e3)
            figures[key] = {"ms": summary(each_ms), "pictures_per_s": 1e3 / float(np.median(each_ms))}
    return figures


def measure_beside_physics(run_dir: Path, duration_s: float, body: str, image_size: tuple[int, int]) -> dict:
    """The task's recording dataflow, an episode recorded throughout while the prober moves the arm."""
    flow, episode = record_run(run_dir, duration_s, body, image_size, task=CUBE_TO_BOX.name)
    return {"joint_state_per_s": flow["joint_state_per_s"], "sim_over_wall": flow["sim_over_wall"],
            "ticks_missed": flow["ticks_missed"], "recorded_s": episode["recorded_s"],
            "new_pictures_per_s": {key: episode["new_pictures_per_s"][key] for key in CAMERAS}}


def run_camera_benchmark(work_dir: Path, duration_s: float, body: str, image_size: tuple[int, int] = IMAGE_SIZE) -> dict:
    print(f"cameras: {PICTURES} pictures from each of the task's cameras, alone ...", flush=True)
    figures: dict = {"image_size": list(image_size), "alone": measure_pictures_alone(body, image_size)}
    print(f"cameras: so101 teleop --task cube_to_box --record's dataflow, {duration_s:g} s ...", flush=True)
    figures["beside_physics"] = measure_beside_physics(work_dir / "cameras", duration_s, body, image_size)
    return figures


def table_lines(figures: dict) -> list[str]:
    alone, beside = figures["alone"], figures["beside_physics"]
    size = "x".join(map(str, figures.get("image_size", IMAGE_SIZE)))
    lines = []
    for key in CAMERAS:
        name = key.rsplit(".", 1)[-1]
        lines += [
            f"{name + ' camera, ' + size + ', alone (ms, p50 | p99)':<52} {alone[key]['ms']['p50']:>10.1f} | {alone[key]['ms']['p99']:<9.1f}",
            f"{'  pictures per s: alone | beside the physics':<52} {alone[key]['pictures_per_s']:>10.1f} | "
            f"{beside['new_pictures_per_s'][key]:<9.1f}",
        ]
    return lines + [
        f"{'task recording: joint_state per s':<52} {beside['joint_state_per_s']:>10.2f}",
        f"{'  simulated / wall time':<52} {beside['sim_over_wall']:>10.4f}",
    ]


def targets(figures: dict, joint_state_target: float, sim_error_target: float) -> list[dict]:
    """The body keeps its rate with both cameras drawing; each camera gives a new picture per frame (30 a second)."""
    from bench.common import target_row

    beside = figures["beside_physics"]
    rows = [
        target_row("task recording: joint_state per s", round(beside["joint_state_per_s"], 2),
                   f">= {joint_state_target}", beside["joint_state_per_s"] >= joint_state_target),
        target_row("task recording: simulated / wall time", round(beside["sim_over_wall"], 4),
                   f"within {sim_error_target:.0%} of 1", abs(beside["sim_over_wall"] - 1) <= sim_error_target),
    ]
    for key in CAMERAS:
        rate = beside["new_pictures_per_s"][key]
        rows.append(target_row(f"{key.rsplit('.', 1)[-1]} camera: new pictures per s while recording", round(rate, 1),
                               f">= {DEFAULT_FPS}", rate >= DEFAULT_FPS))
    return rows
