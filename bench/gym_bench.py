"""`so101 bench --gym`: steps a second of the Gymnasium environment (so101/gym/), beside the dataflow's lockstep.

Four runs, each for a while of wall time: one environment and an async vector of two
(`gymnasium.make_vec(..., num_envs=2, vectorization_mode="async")`, a process each), without
pictures (obs_type state) and with both cameras (obs_type all, at --image-size). A step is one
25 fps frame, as a lockstep frame of `so101 demos` is; the arm sweeps back and forth so the physics
has work, and TimeLimit's resets (750 frames) are counted in. Beside them: the dataflow's lockstep
frames a second, as `so101 bench --demos` saved them (its run without video, one worker).
"""

from __future__ import annotations

import json
import math
import time

import numpy as np

from so101.runtime.dataflow import ROOT

# (obs_type, environments). The vector with pictures before the one environment with them: a process forked
# after its parent drew a picture hangs in its first (Mesa's EGL state is not the child's; docs/loop/gym.md).
RUNS = (("state", 1), ("state", 2), ("all", 2), ("all", 1))
# Without pictures, in process, it should far exceed the dataflow's lockstep: at least this many times its frames a second.
TARGET_OVER_DATAFLOW = 3.0


def sweep_action(step: int, environments: int) -> np.ndarray:
    """The arm's shoulder and elbow swinging ±30° around home every 4 s (LeRobot's units), for each environment."""
    from so101.dataset.features import to_lerobot

    swing = 30.0 * math.sin(2 * math.pi * step / 100)
    action = to_lerobot([swing, swing / 2, -swing / 2, 0.0, 0.0, 20.0])
    return action if environments == 1 else np.tile(action, (environments, 1))


def steps_per_s(body: str, obs_type: str, environments: int, seconds: float, image_size: tuple[int, int],
                warmup_s: float = 1.0) -> dict:
    """Environment steps a second (a vector's step counts each of its environments'), over `seconds`
    after `warmup_s` (the first steps load and draw for the first time)."""
    import gymnasium

    import so101.gym  # noqa: F401  (registers the id)

    options = {"body": body, "obs_type": obs_type, "camera_size": image_size}
    env = (gymnasium.make(so101.gym.ENV_ID, **options) if environments == 1 else
           gymnasium.make_vec(so101.gym.ENV_ID, num_envs=environments, vectorization_mode="async", **options))
    try:
        env.reset(seed=1000 if environments == 1 else [1000 + index for index in range(environments)])
        step, started, counted_from = 0, time.perf_counter(), None
        while True:
            now = time.perf_counter()
            if counted_from is None and now - started >= warmup_s:
                counted_from, first = now, step
            elif counted_from is not None and now - counted_from >= seconds:
                break
            _, _, terminated, truncated, _ = env.step(sweep_action(step, environments))
            if environments == 1 and (terminated or truncated):
                env.reset()
            step += 1
        rate = (step - first) * environments / (now - counted_from)
    finally:
        env.close()
    return {"obs_type": obs_type, "environments": environments, "steps_per_s": round(rate, 1),
            "times_real_time": round(rate / 25, 1), "seconds": round(now - counted_from, 2)}


def dataflow_frames_per_s(body: str) -> float | None:
    """The dataflow's lockstep frames a second without video, one worker, from `so101 bench --demos`' saved result."""
    saved = ROOT / "bench" / "results" / ("latest-demos-mujoco.json" if body == "mujoco" else "latest-demos.json")
    try:
        return float(json.loads(saved.read_text())["demos"]["runs"]["no_video_1_workers"]["frames_per_s"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def run_gym_benchmark(body: str, seconds: float, image_size: tuple[int, int]) -> dict:
    runs = {}
    for obs_type, environments in RUNS:
        key = f"{obs_type}_{environments}_env{'s' if environments > 1 else ''}"
        runs[key] = steps_per_s(body, obs_type, environments, seconds, image_size)
        print(f"  gym, obs_type {obs_type}, {environments} environment(s): {runs[key]['steps_per_s']} steps/s", flush=True)
    return {"runs": runs, "image_size": list(image_size), "dataflow_frames_per_s": dataflow_frames_per_s(body)}


def table_lines(figures: dict) -> list[str]:
    size = "x".join(map(str, figures["image_size"]))
    lines = [f"{'so101/CubeToBox-v0 (steps/s | × real time)':<52}"]
    for run in figures["runs"].values():
        what = "no pictures (state)" if run["obs_type"] == "state" else f"both cameras {size} (all)"
        where = "one environment" if run["environments"] == 1 else f"async vector of {run['environments']}"
        lines.append(f"{what + ', ' + where:<52} {run['steps_per_s']:>8.0f} | {run['times_real_time']:<6.1f}")
    dataflow = figures.get("dataflow_frames_per_s")
    shown = f"{dataflow:>8.0f}" if dataflow is not None else "     n/a"
    lines.append(f"{'the dataflow lockstep, no video (saved --demos run)':<52} {shown}")
    return lines


def targets(figures: dict, joint_state_target: float, sim_error_target: float) -> list[dict]:
    from bench.common import target_row

    dataflow = figures.get("dataflow_frames_per_s")
    one = figures["runs"]["state_1_env"]["steps_per_s"]
    ratio = one / dataflow if dataflow else None
    return [target_row("gym steps/s without pictures, one env / dataflow lockstep frames/s", ratio,
                       f">= {TARGET_OVER_DATAFLOW:g}", ratio is not None and ratio >= TARGET_OVER_DATAFLOW)]
