"""The simulation node's real-time budget, measured against raw PyBullet (issue 4).

    python bench/run_bench.py [--duration 20] [--out bench/results/latest.json] [--quick]
    (or: so101 bench ...)

One run on one machine measures:
  1. raw stepSimulation of the SO-101 in DIRECT mode (the limit), µs per step;
  2. the node's own work per tick in process (nodes/simulation_node.py under
     dora.testing.MockNode): targets + step + state read + Arrow arrays + send;
  3-7. a real headless `dora run` of dataflow.yml, with bench/nodes/prober.py in the
     place of keyboard_control: joint_state/s against 250, ticks missed, tick interval
     and per-tick work p50/p99, joint_cmd -> joint_state latency and the first visible
     move (> 0.3°), simulated over wall time, start-up to the first joint_state, peak
     RSS of the simulation node;
  8. the same with the window open (SO101_MODE gui; on a fresh Xvfb server when no
     display is reachable): joint_state/s, simulated over wall time, latency;
  9. the node's fast mode (SO101_FAST_STEPS): steps per second against the raw rate;
  10. where the node's memory goes: peak RSS after each loading stage, in fresh processes,
     for the course's plain loading and for the node's;
  11. recording (bench/record_bench.py): a picture's cost, pictures drawn inside the loop, the
     body while `so101 teleop --record`'s dataflow records an episode with video, and saving one;
  12. the leader arm (bench/leader_bench.py): the emulated leader moved by hand -> the first
     joint_state that shows it, through `so101 teleop --leader`'s dataflow;
  13. the web view (bench/web_bench.py): the body with five viewers on `so101 teleop --web`'s
     page, viewers elsewhere and browsers on this machine (`--web`: this alone).
  14. the Gymnasium environment (bench/gym_bench.py, `--gym` alone): steps a second of one
     environment and of an async vector of two, without pictures and with both cameras.
  15. a policy's frame -> action round trip in lockstep (bench/round_trip_bench.py, `--round-trip` alone),
     with the policy on the body's daemon and on another daemon of a cluster.
It prints a table and writes the figures, the targets and the machine to a JSON file.
Timings are wall-clock on a shared machine: the load average is recorded with them.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path, PurePath
from typing import Callable

if __package__ in (None, ""):  # run as a script (python bench/run_bench.py): the checkout holds `bench`
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import (  # noqa: E402
    PACED_PROBE_ENV, WARMUP_S, machine_facts, machine_line, realtime_figures, run_dataflow,
    target_lines, target_row, tick_figures, tick_records,
)
from so101.bodies.registry import BODIES  # noqa: E402
from so101.runtime.argtypes import image_size, number, whole_number  # noqa: E402
from so101.dataset.settings import DEFAULT_IMAGE_SIZE  # noqa: E402
from so101.runtime.display import DisplayError, display_available, virtual_display  # noqa: E402
from so101.runtime.dataflow import ROOT, TICK_PERIOD_S  # noqa: E402
from so101.stats import summary  # noqa: E402

DEFAULT_OUT = {"pybullet": ROOT / "bench" / "results" / "latest.json", "mujoco": ROOT / "bench" / "results" / "latest-mujoco.json",
               "real": ROOT / "bench" / "results" / "latest-real.json",
               "cluster": ROOT / "bench" / "results" / "latest-cluster.json",
               "round-trip-sealed": ROOT / "bench" / "results" / "latest-round-trip-sealed.json",
               "web": ROOT / "bench" / "results" / "latest-web.json",
               "cameras": ROOT / "bench" / "results" / "latest-cameras.json",
               "cameras-mujoco": ROOT / "bench" / "results" / "latest-cameras-mujoco.json",
               "demos": ROOT / "bench" / "results" / "latest-demos.json",
               "demos-mujoco": ROOT / "bench" / "results" / "latest-demos-mujoco.json",
               "gym": ROOT / "bench" / "results" / "latest-gym.json",
               "gym-mujoco": ROOT / "bench" / "results" / "latest-gym-mujoco.json",
               "round-trip": ROOT / "bench" / "results" / "latest-round-trip.json"}
# The engine's own call for one 4 ms tick, as the table names it.
RAW_STEP_LABEL = {"pybullet": "raw stepSimulation, DIRECT", "mujoco": "raw mj_step x 2 (one 4 ms tick)"}

TARGETS = {
    "node_work_ratio": 1.5,  # per-tick work / raw step, at most
    "joint_state_per_s": 247.5,  # 99% of 250, at least
    "latency_p99_ms": 5.0,  # at most
    "visible_move_over_latency_ms": 0.5,  # |first visible move - latency|, p50 and p99 each, at most
    "gui_joint_state_per_s": 245.0,  # with the window open, at least
    "sim_over_wall_error": 0.01,  # |sim/wall - 1|, at most
    "startup_s": 3.0,  # at most
    # At most: PyBullet's node colliding the hull files, MuJoCo's drawing nothing (issue 23).
    "peak_rss_mb": {"pybullet": 150.0, "mujoco": 200.0},
    "fast_ratio": 0.90,  # fast-mode steps/s over raw steps/s, at least, with FAST_TARGET_STEPS steps per state
    "save_60s_episode_s": 10.0,  # saving a 60 s episode with video, at most
    # The leader moved by hand -> the body's joint_state showing it, p99, at most: the leader's 10 ms
    # tick and read, the body's 4 ms tick, the transits (the same for MuJoCo's node as PyBullet's).
    "leader_latency_p99_ms": 25.0,
}
FAST_TARGET_STEPS = 100


# -- targets ------------------------------------------------------------------------
def target_rows(figures: dict, body: str = "pybullet") -> list[dict]:
    """Each target with the figure it judges and whether it was met."""
    rows = []

    def row(name, value, target, met):
        rows.append(target_row(name, value, target, met))

    row("per-tick work / raw step (in process, p50)", figures["node_work_in_process"]["ratio_to_raw_p50"],
        f"<= {TARGETS['node_work_ratio']}", figures["node_work_in_process"]["ratio_to_raw_p50"] <= TARGETS["node_work_ratio"])
    dataflow = figures["dataflow"]
    row("joint_state per s (dora run)", dataflow["joint_state_per_s"], f">= {TARGETS['joint_state_per_s']}",
        dataflow["joint_state_per_s"] >= TARGETS["joint_state_per_s"])
    latency = figures["command_latency_ms"]
    row("command latency p99 (ms)", latency["p99"], f"<= {TARGETS['latency_p99_ms']}", latency["p99"] <= TARGETS["latency_p99_ms"])
    visible = latency["first_visible_move_ms"]
    gap_ms = max(abs(visible["p50"] - latency["p50"]), abs(visible["p99"] - latency["p99"]))
    row("first visible move - command latency, p50 and p99 (ms)", gap_ms,
        f"<= {TARGETS['visible_move_over_latency_ms']}", gap_ms <= TARGETS["visible_move_over_latency_ms"])
    ratio = dataflow["sim_over_wall"]
    row("simulated / wall time", ratio, f"1 ± {TARGETS['sim_over_wall_error']}", abs(ratio - 1) <= TARGETS["sim_over_wall_error"])
    row("start-up to first joint_state (s)", dataflow["startup_s"], f"<= {TARGETS['startup_s']}", dataflow["startup_s"] <= TARGETS["startup_s"])
    gui = figures.get("gui")
    if gui and "joint_state_per_s" in gui:
        row("joint_state per s, window open (dora run, GUI)", gui["joint_state_per_s"], f">= {TARGETS['gui_joint_state_per_s']}",
            gui["joint_state_per_s"] >= TARGETS["gui_joint_state_per_s"])
        row("simulated / wall time, window open", gui["sim_over_wall"], f"1 ± {TARGETS['sim_over_wall_error']}",
            abs(gui["sim_over_wall"] - 1) <= TARGETS["sim_over_wall_error"])
    rss = dataflow["peak_rss_mb"]
    rss_target = TARGETS["peak_rss_mb"][body]
    row("peak RSS of the simulation node (MB)", rss, f"<= {rss_target}", rss is not None and rss <= rss_target)
    recording = figures.get("recording")
    if recording:
        while_recording = recording["recording"]
        row("joint_state per s while recording with video", while_recording["joint_state_per_s"],
            f">= {TARGETS['joint_state_per_s']}", while_recording["joint_state_per_s"] >= TARGETS["joint_state_per_s"])
        row("simulated / wall time while recording", while_recording["sim_over_wall"], f"1 ± {TARGETS['sim_over_wall_error']}",
            abs(while_recording["sim_over_wall"] - 1) <= TARGETS["sim_over_wall_error"])
        saving = recording["saving"]
        if saving["episode_s"] == 60:
            row("saving a 60 s episode with video (s)", saving["save_s"], f"<= {TARGETS['save_60s_episode_s']}",
                saving["save_s"] <= TARGETS["save_60s_episode_s"])
    leader = figures.get("leader")
    if leader:
        from bench import leader_bench

        rows.append(leader_bench.target(leader, TARGETS["leader_latency_p99_ms"], body))
    if "web" in figures:
        from bench import web_bench

        rows += web_bench.targets(figures["web"], TARGETS["joint_state_per_s"], TARGETS["sim_over_wall_error"])
    hundred = [run for run in figures["fast_mode"]["runs"] if run["steps_per_state"] == FAST_TARGET_STEPS]
    for run in hundred:
        row(f"fast mode steps/s / raw (SO101_FAST_STEPS={FAST_TARGET_STEPS})", run["ratio_to_raw"],
            f">= {TARGETS['fast_ratio']}", run["ratio_to_raw"] >= TARGETS["fast_ratio"])
    return rows


# -- in-process measurements ----------------------------------------------------------
def raw_stepper(body: str, sim):
    """The engine's own call for one 4 ms period of `sim`, with nothing of this project around it."""
    if body == "mujoco":
        import mujoco

        model, data, substeps = sim.model, sim.data, sim.substeps
        return lambda: mujoco.mj_step(model, data, nstep=substeps)
    import pybullet as p

    client = sim.client
    return lambda: p.stepSimulation(physicsClientId=client)


def measure_raw_step(steps: int, after_sleep_steps: int, body: str = "pybullet") -> dict:
    """One 4 ms step of the engine alone (PyBullet's stepSimulation, MuJoCo's mj_step), the SO-101
    holding home under its position motors (as in the node).

    Also the same step taken after a 4 ms sleep, as a paced node takes it: on this kind
    of machine (a virtual CPU that idles between ticks) that step costs several times
    more, with no dora involved.
    """
    with body_simulator(body) as sim:
        sim.step(250)  # settle: the arm starts a hair off its resting pose
        step = raw_stepper(body, sim)
        clock = time.monotonic_ns
        each_ns = []
        for _ in range(steps):
            start = clock()
            step()
            each_ns.append(clock() - start)
        start = clock()
        for _ in range(steps):
            step()
        loop_us = (clock() - start) / 1e3 / steps
        after_sleep_ns = []
        for _ in range(after_sleep_steps):
            time.sleep(TICK_PERIOD_S)
            start = clock()
            step()
            after_sleep_ns.append(clock() - start)
    each = summary(each_ns, 1e-3)
    after_sleep = summary(after_sleep_ns, 1e-3)
    return {"us_per_step_p50": each["p50"], "us_per_step_p99": each["p99"], "us_per_step_loop_mean": loop_us,
            "steps_per_s": 1e6 / loop_us, "steps": steps,
            "after_4ms_sleep_us_p50": after_sleep["p50"], "after_4ms_sleep_us_p99": after_sleep["p99"]}


def body_simulator(body: str):
    """A headless simulator of `body`, stepped by the tick's period, without a renderer (as the node's)."""
    return BODIES[body].body_class()(mode="direct", time_step_s=TICK_PERIOD_S, renders=False, log=lambda message: None)


def measure_node_work_in_process(ticks: int, work_dir: Path, body: str = "pybullet") -> dict:
    """The body's simulation node's main() over `ticks` timer ticks under MockNode, timed by its own tick log."""
    import importlib

    import pyarrow as pa
    from dora.testing import MockNode

    simulation_node = importlib.import_module(f"nodes.{BODIES[body].node_file.stem}")

    tick_log = work_dir / "in_process_ticks.bin"
    config = {"inputs": {"tick": {"source": f"dora/timer/millis/{TICK_PERIOD_S * 1000:g}", "queue_size": 1}}}
    mock = MockNode([("tick", pa.array([], type=pa.null()))] * ticks, node_config=config)
    env = {"SO101_MODE": "direct", "SO101_LANG": "en", "SO101_TICK_LOG": str(tick_log), "SO101_FAST_STEPS": "0"}
    saved_env = {name: os.environ.get(name) for name in env}
    saved_node = simulation_node.Node
    os.environ.update(env)
    simulation_node.Node = lambda: mock
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            code = simulation_node.main()
    finally:
        simulation_node.Node = saved_node
        for name, value in saved_env.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
    if code != 0:
        raise RuntimeError(f"the simulation node exited with {code} in process")
    ticks = tick_records(tick_log.read_bytes())[250:]  # the same settled arm as the raw step
    return summary([(end - start) / 1e3 for start, end, _ in ticks])


# The node's imports, then the arm loaded one of three ways; peak and current RSS (MB) after each stage.
MEMORY_STAGES_SCRIPT = r"""
import json, sys
def mb():  # VmHWM, not ru_maxrss: the latter keeps the forking parent's peak across exec
    status = dict(line.split(":", 1) for line in open("/proc/self/status"))
    return {"peak": int(status["VmHWM"].split()[0]) / 1024, "current": int(status["VmRSS"].split()[0]) / 1024}
way = sys.argv[1]
stages = {"python": mb()}
import pyarrow, dora, pybullet as p, pybullet_data
from so101 import assets
from so101.bodies import pybullet_hulls, pybullet_sim as simulator
stages["imports (numpy, pyarrow, dora, pybullet)"] = mb()
if way == "node":
    simulator.release_freed_memory()
cid = p.connect(p.DIRECT)
if way != "course":
    for plugin in ("fileIOPlugin", "tinyRendererPlugin"):
        p.unloadPlugin(p.loadPlugin(plugin, physicsClientId=cid), physicsClientId=cid)
stages["DIRECT client"] = mb()
p.setAdditionalSearchPath(pybullet_data.getDataPath(), physicsClientId=cid)
p.loadURDF("plane.urdf", physicsClientId=cid)
urdf = assets.urdf_path()
p.loadURDF(str(pybullet_hulls.urdf_to_load(urdf) if way == "node" else urdf), useFixedBase=True, physicsClientId=cid)
stages["the arm loaded"] = mb()
print(json.dumps(stages))
"""
MEMORY_WAYS = {
    "course": "as the course loads it",
    "plugins": "without the renderer and file cache",
    "node": "and glibc returns freed blocks, and collides the hull files (the node)",
}


def measure_memory_stages() -> dict:
    """Peak and current RSS after each loading stage, one fresh process per way of loading."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    ways = {}
    for way in MEMORY_WAYS:
        result = subprocess.run([sys.executable, "-c", MEMORY_STAGES_SCRIPT, way], capture_output=True, text=True,
                                env=env, timeout=120)
        if result.returncode != 0:
            raise RuntimeError(f"the memory stages ({way}) failed: {result.stderr.strip()[-500:]}")
        ways[way] = json.loads(result.stdout.strip().splitlines()[-1])
    return ways


def measure_gui(run_dir: Path, duration_s: float, probe_env: dict, body: str = "pybullet") -> dict:
    """The paced run again with the window open: on this display, or on a fresh Xvfb server where none
    is reachable (the slow, software-rendered case the window must not hold the physics back in)."""
    try:
        with contextlib.ExitStack() as stack:
            display = os.environ.get("DISPLAY") if display_available() else None
            shown_on = display or "Xvfb"
            display = display or stack.enter_context(virtual_display())
            print(f"dora run with the window open ({shown_on}), {duration_s:g} s ...", flush=True)
            record = run_dataflow(run_dir, duration_s + WARMUP_S, {"SO101_FAST_STEPS": "0", "SO101_MODE": "gui"},
                                  probe_env, display=display, body=body)
    except DisplayError as error:
        print(f"  no window measured: {error}", flush=True)
        return {"skipped": str(error)}
    figures = realtime_figures(record, TICK_PERIOD_S)
    flow, latency = figures["dataflow"], figures["command_latency_ms"]
    return {
        "display": shown_on, "joint_state_per_s": flow["joint_state_per_s"], "sim_over_wall": flow["sim_over_wall"],
        "ticks_missed": flow["ticks_missed"], "ticks_served": flow["ticks_served"],
        "latency_ms": {"p50": latency["p50"], "p99": latency["p99"]},
        "first_visible_move_ms": latency["first_visible_move_ms"], "peak_rss_mb": flow["peak_rss_mb"],
    }


# -- fast mode --------------------------------------------------------------------------
# The raw step beside each fast-mode run takes this share of the first raw measurement's steps.
FAST_RAW_SHARE = 4


def measure_fast_mode(work_dir: Path, steps_per_state: int, duration_s: float, raw_steps: int, body: str) -> dict:
    """The node's fast mode against the raw step taken just before and just after it.

    This machine's speed drifts by up to 2x over minutes (the raw step has gone from 19 to
    42 us between runs of this bench): a raw step measured at the bench's start made the
    ratio 0.65-1.16 depending on the moment. Both sides are medians, so a preempted step or
    batch does not count: the raw step's p50 beside the run, and the p50 of the time from one
    batch's start to the next (its N steps, the state read and sent, the poll for input).
    """
    raw_before = measure_raw_step(raw_steps, 0, body)
    print(f"dora run, fast mode SO101_FAST_STEPS={steps_per_state}, {duration_s:g} s ...", flush=True)
    record = run_dataflow(
        work_dir / f"fast{steps_per_state}", duration_s + WARMUP_S, {"SO101_FAST_STEPS": str(steps_per_state)},
        {"PROBE_PERIOD_S": "0", "PROBE_COUNT_ONLY": "1"}, body=body,
    )
    raw_after = measure_raw_step(raw_steps, 0, body)
    steady_from_ns = record["probe"]["first_state_ns"] + int(WARMUP_S * 1e9)
    ticks = tick_figures([tick for tick in record["ticks"] if tick[0] >= steady_from_ns], TICK_PERIOD_S)
    raw_step_us = (raw_before["us_per_step_p50"] + raw_after["us_per_step_p50"]) / 2
    step_us = ticks["interval_ms"]["p50"] * 1e3 / steps_per_state
    return {
        "steps_per_state": steps_per_state, "steps_per_s": 1e6 / step_us, "ratio_to_raw": raw_step_us / step_us,
        "raw_step_us_p50": {"before": raw_before["us_per_step_p50"], "after": raw_after["us_per_step_p50"]},
        "mean_steps_per_s": ticks["steps_per_s"], "states_per_s": ticks["served_per_s"],
        "sim_over_wall": ticks["steps_per_s"] * TICK_PERIOD_S, "measured_s": ticks["span_s"],
    }


# -- the run --------------------------------------------------------------------------
def run_benchmark(duration_s: float, fast_s: float, fast_steps: list[int], raw_steps: int, node_ticks: int,
                  after_sleep_steps: int, body: str = "pybullet", saved_episode_s: float = 60.0,
                  web_browsers: bool = True) -> dict:
    load_start = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="so101-bench-") as tmp:
        work_dir = Path(tmp)
        print(f"body: {body}; raw engine step ({raw_steps} steps) ...", flush=True)
        raw = measure_raw_step(raw_steps, after_sleep_steps, body)
        print(f"node work in process ({node_ticks} ticks) ...", flush=True)
        node_work = measure_node_work_in_process(node_ticks, work_dir, body)
        node_work["ratio_to_raw_p50"] = node_work["p50"] / raw["us_per_step_p50"]
        print(f"dora run, paced by the 4 ms tick, {duration_s:g} s ...", flush=True)
        paced = run_dataflow(work_dir / "paced", duration_s + WARMUP_S, {"SO101_FAST_STEPS": "0"}, PACED_PROBE_ENV, body=body)
        figures = {"raw_step": raw, "node_work_in_process": node_work, **realtime_figures(paced, TICK_PERIOD_S)}
        figures["gui"] = measure_gui(work_dir / "gui", duration_s, PACED_PROBE_ENV, body)
        from bench import leader_bench

        figures["leader"] = leader_bench.run_leader_benchmark(work_dir, duration_s, body, {"SO101_FAST_STEPS": "0"})
        from bench import web_bench

        figures["web"] = web_bench.run_web_benchmark(work_dir, duration_s, body, browsers=web_browsers)
        figures["fast_mode"] = {"runs": [measure_fast_mode(work_dir, steps, fast_s, raw_steps // FAST_RAW_SHARE, body)
                                         for steps in fast_steps]}
        from bench import record_bench

        figures["recording"] = record_bench.run_recording_benchmark(work_dir, duration_s, body, saved_episode_s)
        if body == "pybullet":  # where PyBullet's loading spends memory; MuJoCo's node peaks far lower
            print("memory, stage by stage ...", flush=True)
            figures["memory_stages_mb"] = measure_memory_stages()
    figures["targets"] = target_rows(figures, body)
    return {
        "body": body,
        "machine": machine_facts(),
        "load_average_1_5_15min": {"start": list(load_start), "end": list(os.getloadavg())},
        "settings": {"tick_ms": TICK_PERIOD_S * 1e3, "duration_s": duration_s, "fast_mode_s": fast_s,
                     "raw_steps": raw_steps, "in_process_ticks": node_ticks, "warmup_s": WARMUP_S,
                     "fast_steps_per_state": fast_steps, "saved_episode_s": saved_episode_s},
        **figures,
    }


def run_alone(only: str, measures: str, body: str, settings: dict, measure: Callable[[Path], dict],
              targets: Callable[[dict, float, float], list[dict]]) -> dict:
    """One part of the benchmark run by itself (`--web`, `--cameras`): `measure(work_dir)` gives its
    figures, kept under `only`, with the machine, its load and the part's targets. `measures` says
    what, for the refusal of the real arm."""
    if body == "real":
        raise RuntimeError(f"--{only} measures {measures}: --body pybullet or mujoco")
    load_start = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="so101-bench-") as tmp:
        figures = measure(Path(tmp))
    return {"body": body, "only": only, "machine": machine_facts(),
            "load_average_1_5_15min": {"start": list(load_start), "end": list(os.getloadavg())},
            "settings": settings, only: figures,
            "targets": targets(figures, TARGETS["joint_state_per_s"], TARGETS["sim_over_wall_error"])}


def run_web_only(duration_s: float, body: str, browsers: bool) -> dict:
    """`--web`: the web view's runs alone."""
    from bench import web_bench

    return run_alone("web", "a simulation", body, {"duration_s": duration_s},
                     lambda work_dir: web_bench.run_web_benchmark(work_dir, duration_s, body, browsers), web_bench.targets)


def run_cameras_only(duration_s: float, body: str, image_size: tuple[int, int]) -> dict:
    """`--cameras`: a task's two cameras, alone and beside the physics."""
    from bench import camera_bench

    return run_alone("cameras", "a simulation's pictures", body, {"duration_s": duration_s, "image_size": list(image_size)},
                     lambda work_dir: camera_bench.run_camera_benchmark(work_dir, duration_s, body, image_size),
                     camera_bench.targets)


def run_demos_only(body: str, image_size: tuple[int, int], quick: bool) -> dict:
    """`--demos`: `so101 demos`' speed with one and two workers, and where a frame's time goes."""
    from bench import demos_bench

    settings = {"episodes": 4 if quick else 20, "video_episodes": 2 if quick else 4, "image_size": list(image_size),
                "stage_frames": 50 if quick else 250}
    return run_alone("demos", "a simulation's episodes", body, settings,
                     lambda work_dir: demos_bench.run_demos_benchmark(
                         work_dir, body, settings["episodes"], settings["video_episodes"], image_size,
                         settings["stage_frames"]),
                     demos_bench.targets)


def run_gym_only(body: str, image_size: tuple[int, int], quick: bool) -> dict:
    """`--gym`: the Gymnasium environment's steps a second, one environment and an async vector of two."""
    from bench import gym_bench

    settings = {"seconds": 2.0 if quick else 10.0, "image_size": list(image_size)}
    return run_alone("gym", "a simulation's environment", body, settings,
                     lambda work_dir: gym_bench.run_gym_benchmark(body, settings["seconds"], image_size),
                     gym_bench.targets)


def alone_table(result: dict) -> str:
    """The table of a part run by itself (`run_alone`'s result)."""
    from bench import camera_bench, demos_bench, gym_bench, web_bench

    only = result["only"]
    title = {"web": "web view", "cameras": "task cameras", "demos": "demonstrations", "gym": "Gymnasium environment"}[only]
    lines = {"web": web_bench.table_lines, "cameras": camera_bench.table_lines,
             "demos": demos_bench.table_lines, "gym": gym_bench.table_lines}[only](result[only])
    machine = result["machine"]
    return "\n".join([f"SO-101 {title} benchmark ({result['body']}), {machine['date']}", machine_line(result), "",
                      *lines, "", *target_lines(result["targets"])])


def table(result: dict) -> str:
    raw, work, flow, latency = result["raw_step"], result["node_work_in_process"], result["dataflow"], result["command_latency_ms"]
    body = result.get("body", "pybullet")
    machine = result["machine"]
    lines = [
        f"SO-101 simulation node benchmark ({body}), {machine['date']}",
        machine_line(result, f"mujoco {machine.get('mujoco')}" if body == "mujoco" else f"pybullet {machine['pybullet']}"),
        "",
        f"{'figure':<52} {'value':>22}",
        f"{RAW_STEP_LABEL[body] + ' (us/step, p50 | loop mean)':<52} {raw['us_per_step_p50']:>10.1f} | {raw['us_per_step_loop_mean']:<9.1f}",
        f"{'  the same step after a 4 ms sleep (us, p50 | p99)':<52} {raw['after_4ms_sleep_us_p50']:>10.1f} | {raw['after_4ms_sleep_us_p99']:<9.1f}",
        f"{'node work per tick in process (us, p50 | p99)':<52} {work['p50']:>10.1f} | {work['p99']:<9.1f}",
        f"{'  ratio to the raw step (p50)':<52} {work['ratio_to_raw_p50']:>10.2f}",
        f"{'dora run: joint_state per s (250 expected)':<52} {flow['joint_state_per_s']:>10.2f}",
        f"{'  ticks missed / served':<52} {flow['ticks_missed']:>10d} / {flow['ticks_served']}",
        f"{'  dora warnings, dropped ticks (start-up | steady)':<52} {flow['dora_dropped_tick_warnings_startup']:>10d} | {flow['dora_dropped_tick_warnings_steady']}",
        f"{'  tick interval (ms, p50 | p99)':<52} {flow['tick_interval_ms']['p50']:>10.3f} | {flow['tick_interval_ms']['p99']:<9.3f}",
        f"{'  per-tick work (us, p50 | p99)':<52} {flow['tick_work_us']['p50']:>10.1f} | {flow['tick_work_us']['p99']:<9.1f}",
        f"{'  joint_cmd -> joint_state latency (ms, p50 | p99)':<52} {latency['p50']:>10.2f} | {latency['p99']:<9.2f}",
        f"{'    of which waiting for the next tick (ms, p50 | p99)':<52} {latency['wait_for_next_tick_ms']['p50']:>10.2f} | {latency['wait_for_next_tick_ms']['p99']:<9.2f}",
        f"{'    from tick start to arrival (ms, p50 | p99)':<52} {latency['tick_start_to_arrival_ms']['p50']:>10.2f} | {latency['tick_start_to_arrival_ms']['p99']:<9.2f}",
        f"{'    probes that missed the next tick / probes':<52} {latency['probes_that_missed_the_next_tick']:>10d} / {latency['count']}",
        f"{'  first visible move, > 0.3° (ms, p50 | p99)':<52} {latency['first_visible_move_ms']['p50']:>10.2f} | {latency['first_visible_move_ms']['p99']:<9.2f}",
        f"{'  simulated / wall time':<52} {flow['sim_over_wall']:>10.4f}",
        f"{'  start-up: dora run -> first joint_state (s)':<52} {flow['startup_s']:>10.2f}",
        f"{'  peak RSS of the simulation node (MB)':<52} {flow['peak_rss_mb'] or float('nan'):>10.1f}",
    ]
    gui = result["gui"]
    if "skipped" in gui:
        lines.append(f"{'dora run, window open':<52} {'not measured: ' + gui['skipped']}")
    else:
        lines += [
            f"{'dora run, window open (' + gui['display'] + '): joint_state per s':<52} {gui['joint_state_per_s']:>10.2f}",
            f"{'  ticks missed / served':<52} {gui['ticks_missed']:>10d} / {gui['ticks_served']}",
            f"{'  joint_cmd -> joint_state latency (ms, p50 | p99)':<52} {gui['latency_ms']['p50']:>10.2f} | {gui['latency_ms']['p99']:<9.2f}",
            f"{'  first visible move, > 0.3° (ms, p50 | p99)':<52} {gui['first_visible_move_ms']['p50']:>10.2f} | {gui['first_visible_move_ms']['p99']:<9.2f}",
            f"{'  simulated / wall time':<52} {gui['sim_over_wall']:>10.4f}",
        ]
    if "leader" in result:  # results from before the leader arm have no leader rows
        from bench import leader_bench

        lines += leader_bench.table_lines(result["leader"])
    if "web" in result:  # results from before the web view have no web rows
        from bench import web_bench

        lines += web_bench.table_lines(result["web"])
    for run in result["fast_mode"]["runs"]:
        label = f"fast mode, SO101_FAST_STEPS={run['steps_per_state']} (steps/s, x raw)"
        lines.append(f"{label:<52} {run['steps_per_s']:>10.0f} | {run['ratio_to_raw']:<9.2f}")
        if "raw_step_us_p50" in run:  # results from before the raw step was taken beside each run have none
            raw_us = run["raw_step_us_p50"]
            lines.append(f"{'  raw step just before | after (us, p50)':<52} {raw_us['before']:>10.1f} | {raw_us['after']:<9.1f}")
    if "recording" in result:
        from bench import record_bench

        lines += record_bench.table_lines(result["recording"])
    stages = result.get("memory_stages_mb")
    if stages:
        lines += ["", f"{'memory, peak | current RSS (MB)':<52} " + " ".join(f"{way:>17}" for way in stages)]
        for stage in next(iter(stages.values())):
            cells = " ".join(f"{stages[way][stage]['peak']:>8.1f} |{stages[way][stage]['current']:>7.1f}" for way in stages)
            lines.append(f"{'  ' + stage:<52} {cells}")
        lines += [f"  {way}: {MEMORY_WAYS[way]}" for way in stages]
    lines += ["", *target_lines(result["targets"])]
    return "\n".join(lines)


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="so101 bench", description=__doc__.splitlines()[0])
    add_arguments(parser)
    return parser.parse_args(argv)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--duration", type=_positive_seconds, default=20.0,
                        help="seconds of the paced `dora run` measurement, after start-up (default 20)")
    parser.add_argument("--body", choices=list(BODIES), default="pybullet",
                        help="which node to measure: pybullet (the course's, default), mujoco, or real (the real arm's "
                        "driver, against so101 fake-arm's emulated bus)")
    parser.add_argument("--cluster", action="store_true",
                        help="measure the simulation across two dora daemons on 127.0.0.1 (dataflow_cluster.yml), next "
                        "to one daemon: joint_state rate and command latency")
    parser.add_argument("--web", action="store_true",
                        help="measure only the web view: the body with five viewers on `so101 teleop --web`'s page, "
                        "then five browsers, --duration seconds each (600 shows whether its memory grows)")
    parser.add_argument("--cameras", action="store_true",
                        help="measure only a task's two cameras (cube_to_box, 320x240): pictures a second each, drawn "
                        "alone and while `so101 teleop --task cube_to_box --record`'s dataflow runs, --duration seconds")
    parser.add_argument("--demos", action="store_true",
                        help="measure only `so101 demos` (cube_to_box, the expert): episodes a minute and × real time "
                        "without video and with both cameras, one worker and two, and where a frame's time goes")
    parser.add_argument("--gym", action="store_true",
                        help="measure only the Gymnasium environment (so101/CubeToBox-v0, in process): steps a second of "
                        "one environment and of an async vector of two, without pictures and with both cameras")
    parser.add_argument("--round-trip", action="store_true",
                        help="measure only a policy's frame -> action round trip in lockstep (so101 eval's run), the "
                        "policy on the body's daemon, then on another daemon: on 127.0.0.1, or on the cluster "
                        "--coordinator names")
    parser.add_argument("--policy", type=Path, default=None, metavar="DIR",
                        help="--round-trip: the policy (default: the tiny ACT in tests/data/policy_act_tiny)")
    parser.add_argument("--policy-python", type=Path, default=None, metavar="PY",
                        help="--round-trip: the Python that runs it (default: so101 policy-env's; with --coordinator, "
                        "its path on the policy's machine)")
    parser.add_argument("--episodes", type=whole_number(1, 1000), default=None, metavar="N",
                        help="--round-trip: episodes each way (default 10; --quick 2)")
    parser.add_argument("--seed", type=whole_number(0, 2**31), default=1000, metavar="S",
                        help="--round-trip: the first episode's seed (default 1000)")
    parser.add_argument("--coordinator", default=None, metavar="ADDR[:PORT]",
                        help="--round-trip on the dora cluster of this coordinator (its token in DORA_AUTH_TOKEN), with "
                        "--machine and --policy-machine")
    parser.add_argument("--machine", default=None, metavar="ID",
                        help="--coordinator: this machine's daemon, where the body runs, and the policy the first time")
    parser.add_argument("--policy-machine", default=None, metavar="NAME",
                        help="--coordinator: the daemon the policy runs on the second time")
    parser.add_argument("--root", type=PurePath, default=None, metavar="FOLDER",
                        help="--coordinator: the project's folder on the policy's machine (default: this checkout's)")
    parser.add_argument("--sealed", action="store_true",
                        help="--round-trip across the sealed rig (as root): machines arm and desk of network namespaces "
                        "on this computer, WireGuard only between them (docs/clusters-sealed.md)")
    parser.add_argument("--image-size", type=image_size, default=DEFAULT_IMAGE_SIZE, metavar="WxH",
                        help=f"--cameras, --demos, --gym: the pictures' size (default {DEFAULT_IMAGE_SIZE})")
    parser.add_argument("--out", type=Path, default=None,
                        help="JSON file to write (default " + ", ".join(f"{path.relative_to(ROOT)} for {body}" for body, path in DEFAULT_OUT.items()) + ")")
    parser.add_argument("--quick", action="store_true",
                        help="a short smoke run (3 s paced, 2 s per fast-mode run, fewer in-process steps, a 5 s episode saved; about a minute in all); not for the docs")
    parser.add_argument("--show", type=Path, metavar="JSON",
                        help="print the table of a saved result (e.g. bench/results/latest.json) and measure nothing")
    parser.add_argument("--stale", action="store_true",
                        help="measure nothing: list the saved results of bench/results/ that a later commit's change to "
                        "the code they measure has left out of date, each with the command that reruns it")


_positive_seconds = number(lambda value: 0 < value <= 3600, "a number of seconds above 0 and at most 3600")


def round_trip_place(args: argparse.Namespace):
    """--round-trip's cluster (None: a loopback one of its own), or what is wrong with its options, in one line."""
    from so101.launch.on_cluster import cluster_place

    own = [option for option, value in (("--policy", args.policy), ("--policy-python", args.policy_python),
                                        ("--episodes", args.episodes), ("--coordinator", args.coordinator),
                                        ("--machine", args.machine), ("--policy-machine", args.policy_machine),
                                        ("--root", args.root)) if value is not None]
    if args.sealed:
        own.append("--sealed")
    if own and not args.round_trip:
        return f"{', '.join(own)}: --round-trip's options; they go with --round-trip"
    if not args.round_trip:
        return None
    if args.sealed and (args.coordinator or args.machine or args.policy_machine or args.root):
        return "--round-trip --sealed runs on a cluster of its own: it goes without --coordinator, --machine, " \
               "--policy-machine and --root"
    place = cluster_place(args, "the body runs")
    if place is not None and not isinstance(place, str) and place.policy_machine is None:
        return "--round-trip on a cluster needs --policy-machine NAME: the daemon to run the policy on, against --machine's"
    return place


def table_of(result: dict) -> str:
    """The table `so101 bench` prints for a result of any of its kinds (as `--show` prints a saved one)."""
    from bench import cluster_bench, real_bench, round_trip_bench

    tables = {"real": real_bench.table, "cluster": cluster_bench.table, "web": alone_table, "cameras": alone_table,
              "demos": alone_table, "gym": alone_table, "round-trip": round_trip_bench.table,
              "round-trip-sealed": round_trip_bench.table}
    return tables.get(result.get("only", result.get("body")), table)(result)


def print_stale() -> int:
    """`--stale`: the out-of-date results, one line each (exit 1), or that all are up to date (0)."""
    from bench import staleness

    if not staleness.has_history(ROOT):
        print("so101 bench: --stale reads git's history, and this checkout has none (or a shallow one)", file=sys.stderr)
        return 2
    lines = staleness.stale_lines(ROOT)
    print("\n".join(lines) if lines else f"every result in {staleness.RESULTS} is newer than the code it measures")
    return 1 if lines else 0


def main(argv=None) -> int:
    return run(parse_args(argv))


def run(args: argparse.Namespace) -> int:
    """The benchmark for parsed options (`so101 bench` calls this)."""
    # Here, not at the top: every `so101` command builds this parser, and these bring the
    # serial bus, the fake arm and the cluster (about 0.1 s of imports) that only a run needs.
    from bench import cluster_bench, real_bench, round_trip_bench

    if args.stale:
        return print_stale()
    if args.show is not None:
        try:
            shown = json.loads(args.show.read_text(encoding="utf-8"))
            print(table_of(shown))
        except OSError as error:
            print(f"so101 bench: cannot read {args.show}: {error.strerror or error}", file=sys.stderr)
            return 2
        except (ValueError, KeyError, TypeError) as error:
            print(f"so101 bench: {args.show} is not a result of so101 bench ({type(error).__name__}: {error})", file=sys.stderr)
            return 2
        return 0
    if args.quick:
        settings = dict(duration_s=3.0, fast_s=2.0, fast_steps=[1, 100], raw_steps=5000, node_ticks=1500, after_sleep_steps=100,
                        saved_episode_s=5.0, web_browsers=False)
    else:
        settings = dict(duration_s=args.duration, fast_s=5.0, fast_steps=[1, 10, 100], raw_steps=40000, node_ticks=10000, after_sleep_steps=1000)
    kind = ("cluster" if args.cluster else "web" if args.web else "cameras" if args.cameras else "demos" if args.demos
            else "gym" if args.gym else "round-trip-sealed" if args.round_trip and args.sealed
            else "round-trip" if args.round_trip else args.body)
    place = round_trip_place(args)
    if isinstance(place, str):
        print(f"so101 bench: {place}", file=sys.stderr)
        return 2
    try:
        if args.round_trip and args.sealed:
            options = [*(["--policy", str(args.policy)] if args.policy else []),
                       *(["--policy-python", str(args.policy_python)] if args.policy_python else []),
                       *(["--episodes", str(args.episodes)] if args.episodes else []),
                       "--seed", str(args.seed), *(["--quick"] if args.quick else [])]
            result = round_trip_bench.run_sealed_round_trip(options)
        elif args.round_trip:
            result = round_trip_bench.run_round_trip_benchmark(
                args.policy or round_trip_bench.DEFAULT_POLICY, args.policy_python,
                args.episodes or (2 if args.quick else 10), args.seed, 4.0 if args.quick else None, place)
        elif args.cluster:
            result = cluster_bench.run_cluster_benchmark(settings["duration_s"])
        elif args.web:
            result = run_web_only(settings["duration_s"], args.body, browsers=not args.quick)
        elif args.cameras:
            result = run_cameras_only(settings["duration_s"], args.body, args.image_size)
        elif args.demos:
            result = run_demos_only(args.body, args.image_size, args.quick)
        elif args.gym:
            result = run_gym_only(args.body, args.image_size, args.quick)
        elif args.body == "real":
            result = real_bench.run_real_benchmark(settings["duration_s"], exchanges=500 if args.quick else 3000)
        else:
            result = run_benchmark(**settings, body=args.body)
    except RuntimeError as error:
        print(f"so101 bench: {error}", file=sys.stderr)
        return 1
    result["settings"]["quick"] = args.quick
    print()
    print(table_of(result))
    out = args.out or DEFAULT_OUT[f"{kind}-mujoco" if kind in ("cameras", "demos", "gym") and args.body == "mujoco" else kind]
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"\nwrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
