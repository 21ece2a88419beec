"""A task's cameras (issue "Something to pick up"): `so101 bench --cameras` runs these for a simulated body.

  1. pictures alone: the camera node's renderer (MuJoCo's for every body: the task's scene, its pictures light) draws
     the front and the wrist camera at 320x240 (or --image-size) in turn, nothing else running: ms a picture, and
     so the pictures a second each camera could give;
  2. the renderers' options, each in a process of its own (they are chosen at start-up): the front
     camera's ms a picture with the model's full meshes against the cameras' meshes; PyBullet's
     TinyRenderer (what the camera drew with before so101.bodies.task_cameras) against its EGL plugin (OpenGL, here Mesa's
     llvmpipe); MuJoCo's EGL on one Mesa thread (the camera's) against two, and OSMesa where installed;
  3. beside the physics: `so101 teleop --task cube_to_box --record`'s dataflow (the body, the
     camera node, the recorder with both videos) while the prober moves the arm: the body's
     joint_state/s and simulated/wall time, and the new pictures a second each video holds.
"""

from __future__ import annotations

import argparse
import ctypes.util
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np

from bench.record_bench import record_run
from so101.bodies.camera import WRIST_CAMERA
from so101.bodies.task_cameras import IMAGE_SIZE
from so101.bodies.registry import BODIES
from so101.dataset.features import IMAGE_KEY, WRIST_IMAGE_KEY
from so101.runtime.dataflow import TICK_PERIOD_S
from so101.stats import summary
from so101.tasks import CUBE_TO_BOX

PICTURES = 20  # poses drawn by each camera in the in-process timing
# A video's frames in which the arm moved: at least this share hold a new picture.
NEW_WHILE_MOVING_TARGET = 0.9
CAMERAS = {IMAGE_KEY: None, WRIST_IMAGE_KEY: WRIST_CAMERA}  # None: the body's default (front) camera


# Renderer options: name -> (environment, full meshes, PyBullet's EGL plugin). The first of each body is the camera's own.
RENDERERS = {
    "pybullet": {
        "TinyRenderer, cameras' meshes": ({}, False, False),
        "TinyRenderer, full meshes": ({}, True, False),
        "EGL plugin, cameras' meshes": ({}, False, True),
    },
    "mujoco": {
        "EGL, 1 Mesa thread, cameras' meshes": ({"MUJOCO_GL": "egl", "LP_NUM_THREADS": "1"}, False, False),
        "EGL, 1 Mesa thread, full meshes": ({"MUJOCO_GL": "egl", "LP_NUM_THREADS": "1"}, True, False),
        "EGL, 2 Mesa threads, cameras' meshes": ({"MUJOCO_GL": "egl", "LP_NUM_THREADS": "2"}, False, False),
        "OSMesa, 1 Mesa thread, cameras' meshes": ({"MUJOCO_GL": "osmesa", "PYOPENGL_PLATFORM": "osmesa",
                                                       "LP_NUM_THREADS": "1"}, False, False),
    },
}


def draw_timed(sim, image_size: tuple[int, int], camera_options: dict) -> tuple[list[float], np.ndarray]:
    """ms for each of PICTURES poses drawn, after one picture to set the renderer up; and the first pose's picture."""
    sim.render_rgb(*image_size, **camera_options)
    first = None
    each_ms = []
    for index in range(PICTURES):
        sim.show_pose_deg([3.0 * index, -2.0 * index, 2.0 * index, 10, 4.0 * index, 30])
        start = time.perf_counter()
        picture = sim.render_rgb(*image_size, **camera_options)
        each_ms.append((time.perf_counter() - start) * 1e3)
        first = picture if first is None else first
    return each_ms, first


def camera_simulator(body: str):
    """`body`'s own simulator, its pictures light, with the task's scene: MuJoCo's is what the camera node
    draws every body's task with (so101.bodies.task_cameras); PyBullet's is measured for comparison."""
    return BODIES[body].body_class()(mode="direct", time_step_s=TICK_PERIOD_S, log=lambda message: None,
                                     task=CUBE_TO_BOX, light_pictures=True)


def picture_figures(each_ms: list[float]) -> dict:
    return {"ms": summary(each_ms), "pictures_per_s": 1e3 / float(np.median(each_ms))}


def measure_pictures_alone(body: str, image_size: tuple[int, int]) -> dict:
    """Each camera's pictures of the task's scene, drawn as the camera node draws them, ms each; and who
    drew them (the renderer, its back end, the device)."""
    from so101.bodies.task_cameras import mujoco_drawn_by

    with camera_simulator("mujoco") as sim:
        figures = {key: picture_figures(draw_timed(sim, image_size, {} if camera is None else {"camera": camera})[0])
                   for key, camera in CAMERAS.items()}
        figures["drawn_by"] = mujoco_drawn_by()  # the context the pictures were drawn in is current here
    return figures


def measure_renderer(body: str, name: str, image_size: tuple[int, int], picture_file: Path) -> dict:
    """One renderer option's front pictures, in this process (started for it by measure_renderers);
    the first one saved to `picture_file` (.npy) to compare."""
    _, full_meshes, egl_plugin = RENDERERS[body][name]
    module = sys.modules[BODIES[body].body_class().__module__]
    if full_meshes:
        module.camera_meshes = lambda model_dir, log: None  # type: ignore[attr-defined]
    if egl_plugin:  # loaded before anything else: the plugin draws only the objects loaded after it
        import pkgutil

        import pybullet as p

        connect, camera_image = p.connect, p.getCameraImage

        def connect_with_plugin(*args: object) -> int:
            client = connect(*args)
            loader = pkgutil.get_loader("eglRenderer")
            p.loadPlugin(loader.get_filename(), "_eglRendererPlugin", physicsClientId=client)  # type: ignore[union-attr]
            return client

        module.p.connect = connect_with_plugin
        module.p.getCameraImage = lambda *args, **kwargs: camera_image(
            *args, **{**kwargs, "renderer": p.ER_BULLET_HARDWARE_OPENGL})
    with camera_simulator(body) as sim:
        each_ms, first = draw_timed(sim, image_size, {})
    np.save(picture_file, first)
    return picture_figures(each_ms)


def measure_renderers(body: str, image_size: tuple[int, int], work_dir: Path) -> dict:
    """Each of the body's renderer options in a fresh process: its front pictures' ms and how far its
    picture is from the camera's own (the first option's: the mean difference of a channel, of 255),
    or why it was not measured."""
    figures = {}
    work_dir.mkdir(parents=True, exist_ok=True)
    camera_picture = None
    for index, (name, (environment, _, _)) in enumerate(RENDERERS[body].items()):
        picture_file = work_dir / f"renderer-{index}.npy"
        if environment.get("MUJOCO_GL") == "osmesa" and ctypes.util.find_library("OSMesa") is None:
            figures[name] = {"skipped": "libOSMesa is not installed"}
            continue
        result = subprocess.run(
            [sys.executable, "-m", "bench.camera_bench", "--renderer", name, "--body", body,
             "--image-size", "x".join(map(str, image_size)), "--picture", str(picture_file)],
            env={**os.environ, **environment}, capture_output=True, text=True, timeout=300,
            cwd=Path(__file__).resolve().parents[1],
        )
        lines = result.stdout.strip().splitlines()
        if result.returncode != 0 or not lines:
            figures[name] = {"skipped": f"failed: {(result.stderr.strip().splitlines() or ['no output'])[-1]}"}
        else:
            figures[name] = json.loads(lines[-1])
            picture = np.load(picture_file).astype(np.int16)
            camera_picture = picture if camera_picture is None else camera_picture
            figures[name]["differs_from_camera"] = float(np.mean(np.abs(picture - camera_picture)))
    return figures


def cpu_seconds(folder: Path) -> dict[int, tuple[str, float]]:
    """Each process working in `folder` (a dataflow's: dora and its nodes, which dora starts there):
    pid -> (its name: a Python script's stem, else its program's, its CPU seconds so far)."""
    ticks_per_s = os.sysconf("SC_CLK_TCK")
    found = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            if Path(os.readlink(entry / "cwd")) != folder:
                continue
            arguments = (entry / "cmdline").read_bytes().decode(errors="replace").split("\0")
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        scripts = [Path(argument).stem for argument in arguments if argument.endswith(".py")]
        modules = [module for flag, module in zip(arguments, arguments[1:]) if flag == "-m"]
        program = arguments[1:] if Path(arguments[0]).name.startswith("python") else arguments  # `dora run` is Python's
        name = scripts[0] if scripts else modules[0] if modules else " ".join(Path(part).name for part in program[:2])
        found[int(entry.name)] = (name, (int(fields[11]) + int(fields[12])) / ticks_per_s)  # utime + stime
    return found


def cpu_shares_during(folder: Path, shares: dict[str, float]) -> Callable[[float], None]:
    """A run_dataflow `during` that waits out the measured time and fills `shares`: each process
    name's CPU time over it, in cores (1.0: a whole core throughout)."""

    def during(duration_s: float) -> None:
        before, start = cpu_seconds(folder), time.monotonic()
        time.sleep(duration_s)
        after, elapsed_s = cpu_seconds(folder), time.monotonic() - start
        for pid, (name, seconds) in after.items():
            if pid in before:
                shares[name] = shares.get(name, 0.0) + (seconds - before[pid][1]) / elapsed_s

    return during


def measure_beside_physics(run_dir: Path, duration_s: float, body: str, image_size: tuple[int, int]) -> dict:
    """The task's recording dataflow, an episode recorded throughout while the prober moves the arm,
    and where the CPU time goes meanwhile."""
    shares: dict[str, float] = {}
    flow, episode = record_run(run_dir, duration_s, body, image_size, task=CUBE_TO_BOX.name,
                               during=cpu_shares_during(run_dir.resolve(), shares))
    return {"joint_state_per_s": flow["joint_state_per_s"], "sim_over_wall": flow["sim_over_wall"],
            "ticks_missed": flow["ticks_missed"], "recorded_s": episode["recorded_s"],
            "new_pictures_per_s": {key: episode["new_pictures_per_s"][key] for key in CAMERAS},
            "new_while_moving": {key: episode["new_while_moving"][key] for key in CAMERAS},
            "cpu_cores": dict(sorted(shares.items(), key=lambda item: -item[1]))}


def run_camera_benchmark(work_dir: Path, duration_s: float, body: str, image_size: tuple[int, int] = IMAGE_SIZE) -> dict:
    print(f"cameras: {PICTURES} pictures from each of the task's cameras, alone ...", flush=True)
    figures: dict = {"image_size": list(image_size), "alone": measure_pictures_alone(body, image_size)}
    print(f"cameras: the renderers' options, {PICTURES} front pictures each ...", flush=True)
    figures["renderers"] = measure_renderers(body, image_size, work_dir / "renderers")
    print(f"cameras: so101 teleop --task cube_to_box --record's dataflow, {duration_s:g} s ...", flush=True)
    figures["beside_physics"] = measure_beside_physics(work_dir / "cameras", duration_s, body, image_size)
    return figures


def table_lines(figures: dict) -> list[str]:
    alone, beside = figures["alone"], figures["beside_physics"]
    size = "x".join(map(str, figures.get("image_size", IMAGE_SIZE)))
    lines = [f"{'pictures drawn by':<26} {alone['drawn_by']}"] if "drawn_by" in alone else []
    for key in CAMERAS:
        name = key.rsplit(".", 1)[-1]
        lines += [
            f"{name + ' camera, ' + size + ', alone (ms, p50 | p99)':<52} {alone[key]['ms']['p50']:>10.1f} | {alone[key]['ms']['p99']:<9.1f}",
            f"{'  pictures per s: alone | beside the physics':<52} {alone[key]['pictures_per_s']:>10.1f} | "
            f"{beside['new_pictures_per_s'][key]:<9.1f}",
        ]
        if "new_while_moving" in beside:  # absent from results saved before it was measured
            lines.append(f"{'  new pictures while the arm moves (share of frames)':<52} "
                         f"{beside['new_while_moving'][key]:>10.0%}")
    renderers = figures.get("renderers", {})  # absent from results saved before they were measured
    if renderers:
        lines.append("front camera, each renderer option (ms, p50 | p99; the picture's mean difference from the camera's, of 255):")
    for name, renderer in renderers.items():
        label = f"  {name}"
        if "skipped" in renderer:
            lines.append(f"{label:<52} not measured: {renderer['skipped']}")
        else:
            lines.append(f"{label:<52} {renderer['ms']['p50']:>10.1f} | {renderer['ms']['p99']:<9.1f}"
                         f"{renderer['differs_from_camera']:>6.1f}")
    lines += [
        f"{'task recording: joint_state per s':<52} {beside['joint_state_per_s']:>10.2f}",
        f"{'  simulated / wall time':<52} {beside['sim_over_wall']:>10.4f}",
    ]
    cores = beside.get("cpu_cores", {})  # absent from results saved before it was measured
    if cores:
        lines.append(f"{'  CPU while recording, in cores: all of it':<52} {sum(cores.values()):>10.2f}")
    for name, share in cores.items():
        if share >= 0.005:
            lines.append(f"{'    ' + name:<52} {share:>10.2f}")
    return lines


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
        share = beside["new_while_moving"][key]
        rows.append(target_row(f"{key.rsplit('.', 1)[-1]} camera: new pictures while the arm moves", round(share, 3),
                               f">= {NEW_WHILE_MOVING_TARGET}", share >= NEW_WHILE_MOVING_TARGET))
    return rows


def main() -> int:
    """One renderer option, measured in this process (measure_renderers starts it): its figures as JSON."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("--body", choices=sorted(RENDERERS), required=True)
    parser.add_argument("--renderer", required=True)
    parser.add_argument("--image-size", required=True)
    parser.add_argument("--picture", type=Path, required=True)
    args = parser.parse_args()
    width, height = (int(value) for value in args.image_size.split("x"))
    print(json.dumps(measure_renderer(args.body, args.renderer, (width, height), args.picture)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
