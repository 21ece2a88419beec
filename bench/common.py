"""What the benchmarks share (bench/run_bench.py, cluster_bench.py, real_bench.py).

The prober's records and the simulation node's tick log, read into figures; `dora run` of a
body's dataflow with bench/nodes/prober.py in the place of keyboard_control; the machine a
result was measured on, and the lines every table prints about it and its targets.
"""

from __future__ import annotations

import bisect
import contextlib
import datetime
import importlib.metadata
import json
import os
import platform
import subprocess
import time
from array import array
from pathlib import Path
from typing import Callable

from so101.bodies.registry import BODIES
from so101.runtime.dataflow import ROOT, dataflow_copy, write_dataflow
from so101.runtime.processes import processes_with_env, stop_process
from so101.runtime.venv import dora_executable, env_with_bin_first
from so101.bodies.window import WINDOW_SHOWING
from so101.stats import summary

PROBER = ROOT / "bench" / "nodes" / "prober.py"
FIRST_STATE_MARK = "bench: first joint_state"
# A probe moves a joint by 8° (4° in its first move); the first step after it moves
# the joint by 0.4° to 0.69°, the arm at rest drifts by far less than this.
MOVED_THRESHOLD_DEG = 0.01
# A move a person sees: the arm moves on the first tick that applies the command.
VISIBLE_MOVE_DEG = 0.3
PROBE_STEP_DEG = "4"
# The paced runs' probes: a 4° move every 75 ms.
PACED_PROBE_ENV = {"PROBE_PERIOD_S": "0.075", "PROBE_STEP_DEG": PROBE_STEP_DEG}
WARMUP_S = 1.0  # left out of the rates: the first second after start-up is not steady


# -- the records, read ----------------------------------------------------------------
def tick_records(raw: bytes) -> list[tuple[int, int, int]]:
    """The simulation node's SO101_TICK_LOG file: (start ns, end ns, physics steps so far) of each tick."""
    numbers = array("q")
    numbers.frombytes(raw[: len(raw) - len(raw) % (3 * numbers.itemsize)])
    return list(zip(numbers[0::3], numbers[1::3], numbers[2::3]))


def tick_figures(ticks: list[tuple[int, int, int]], period_s: float) -> dict:
    """Interval and work statistics of the ticks served, the ticks missed between them, and the
    physics steps taken.

    A gap of k periods (rounded) between two served ticks means k - 1 timer ticks were
    dropped: with queue_size 1 a tick that arrives while the node is busy replaces the
    waiting one (the node then takes their steps with the next one).
    """
    starts = [start for start, _, _ in ticks]
    intervals_s = [(b - a) / 1e9 for a, b in zip(starts, starts[1:])]
    missed = sum(max(0, round(interval / period_s) - 1) for interval in intervals_s)
    span_s = (ticks[-1][1] - ticks[0][0]) / 1e9 if ticks else 0.0
    return {
        "ticks_served": len(ticks),
        "ticks_missed": missed,
        "span_s": span_s,
        "served_per_s": (len(ticks) - 1) / ((starts[-1] - starts[0]) / 1e9) if len(ticks) > 1 else float("nan"),
        # The steps taken from the end of the first tick to the end of the last, over that time.
        "steps_per_s": (ticks[-1][2] - ticks[0][2]) / ((ticks[-1][1] - ticks[0][1]) / 1e9) if len(ticks) > 1 else float("nan"),
        "interval_ms": summary(intervals_s, 1e3),
        "work_us": summary([(end - start) / 1e3 for start, end, _ in ticks]),
    }


def states_per_s(states: list, from_ns: int, to_ns: int | None = None) -> tuple[float, float]:
    """(joint_state per second, seconds measured) over the states the prober had that were sent
    from `from_ns` on (up to `to_ns`): by when each was sent, not when it arrived, so a prober
    that stalls and then takes its queue at once does not count a burst as a rate."""
    sent_ns = sorted(state[3] for state in states if state[3] >= from_ns and (to_ns is None or state[3] <= to_ns))
    span_s = (sent_ns[-1] - sent_ns[0]) / 1e9
    return (len(sent_ns) - 1) / span_s, span_s


def reflecting_states(states: list, commands: list, joints: list[int], threshold_deg: float = MOVED_THRESHOLD_DEG) -> list[tuple[int, int]]:
    """For each joint_cmd probe: (send ns, arrival ns of the first joint_state that shows the joint moving toward it).

    states: [arrival ns, angle of joints[0], angle of joints[1], ...] in arrival order;
    commands: [send ns, joint, target deg]. "Shows it": the angle differs from the last
    state received before the send by more than threshold_deg, toward the target.
    A probe no state reflects (the run ended first) is left out.
    """
    pairs = []
    position = 0
    for send_ns, joint, target_deg in commands:
        column = 1 + joints.index(int(joint))
        while position < len(states) and states[position][0] <= send_ns:
            position += 1
        if position == 0:
            continue
        before_deg = states[position - 1][column]
        direction = 1.0 if target_deg > before_deg else -1.0
        for state in states[position:]:
            if (state[column] - before_deg) * direction > threshold_deg:
                pairs.append((send_ns, state[0]))
                break
    return pairs


def latency_breakdown(pairs: list[tuple[int, int]], tick_starts_ns: list[int]) -> dict:
    """Where each probe's latency went, with the simulation node's tick starts (same clock).

    wait: from sending to the next tick's start; deliver: from the start of the tick
    that published the reflecting state to its arrival (the tick's work + transit);
    a probe "missed its tick" when the state came from a later tick than the first one
    after sending (the command reached the node after that tick had begun).
    """
    latencies, waits, delivers, missed = [], [], [], 0
    for send_ns, arrival_ns in pairs:
        next_tick = bisect.bisect_right(tick_starts_ns, send_ns)
        serving_tick = bisect.bisect_right(tick_starts_ns, arrival_ns) - 1
        if next_tick >= len(tick_starts_ns) or serving_tick < 0:
            continue
        latencies.append((arrival_ns - send_ns) / 1e6)
        waits.append((tick_starts_ns[next_tick] - send_ns) / 1e6)
        delivers.append((arrival_ns - tick_starts_ns[serving_tick]) / 1e6)
        missed += serving_tick > next_tick
    return {**summary(latencies), "wait_for_next_tick_ms": summary(waits),
            "tick_start_to_arrival_ms": summary(delivers), "probes_that_missed_the_next_tick": missed}


def dropped_tick_warnings(jsonl_text: str, first_state_epoch_s: float) -> tuple[int, int]:
    """dora's warnings about discarded `tick` events (queue_size 1), before and after the first joint_state.

    jsonl_text: the simulation node's log_simulation.jsonl that `dora run` writes under out/.
    """
    before = after = 0
    for line in jsonl_text.splitlines():
        with contextlib.suppress(ValueError, KeyError, TypeError):
            entry = json.loads(line)
            if entry["level"] == "warn" and "Discarding event for input `tick`" in entry["msg"]:
                when = datetime.datetime.fromisoformat(entry["ts"].replace("Z", "+00:00")).timestamp()
                # The log's stamps are whole milliseconds.
                if when < first_state_epoch_s + 0.001:
                    before += 1
                else:
                    after += 1
    return before, after


# -- the machine and the tables -------------------------------------------------------
def machine_facts() -> dict:
    """The machine and the versions a result was measured with, and the date."""
    cpu = platform.processor() or ""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break

    def version(name):
        try:
            return importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            return None

    return {
        "cpu": cpu, "cores": os.cpu_count(), "platform": platform.platform(),
        "python": platform.python_version(), "dora_rs": version("dora-rs"), "dora_rs_cli": version("dora-rs-cli"),
        "pybullet": version("pybullet"), "mujoco": version("mujoco"), "pyarrow": version("pyarrow"), "numpy": version("numpy"),
        "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
    }


def machine_line(result: dict, engine: str = "") -> str:
    """The table's second line: the machine, the versions (and `engine`'s), the load average at start and end."""
    machine = result["machine"]
    return (f"{machine['cpu']}, {machine['cores']} cores, Python {machine['python']}, dora-rs {machine['dora_rs']}"
            + (f", {engine}" if engine else "") + "; load average at start/end "
            + " / ".join(f"{result['load_average_1_5_15min'][key][0]:.2f}" for key in ("start", "end")))


def target_row(figure: str, value, target: str, met) -> dict:
    """One target with the figure it judges and whether it was met."""
    return {"figure": figure, "value": value, "target": target, "met": bool(met)}


def target_lines(rows: list[dict]) -> list[str]:
    """The table's closing "targets:" lines."""
    lines = ["targets:"]
    for row in rows:
        value = row["value"]
        shown = "n/a" if value is None else f"{value:.3f}"
        lines.append(f"  {'met   ' if row['met'] else 'MISSED'} {row['figure']:<58} {shown:>9}  (target {row['target']})")
    return lines


# -- dora run -------------------------------------------------------------------------
def bench_dataflow(path: Path, sim_env: dict, probe_env: dict, body: str = "pybullet",
                   extend: Callable[[dict], None] | None = None) -> None:
    """The body's dataflow file as it is, with absolute paths, the simulation headless unless sim_env
    says otherwise, `extend` applied (nodes added: the recorder), and the prober as keyboard_control."""
    descriptor = dataflow_copy({"SO101_MODE": "direct", "SO101_LANG": "en", **sim_env}, BODIES[body].dataflow_file)
    if extend is not None:
        extend(descriptor)
    put_prober(descriptor, probe_env)
    write_dataflow(descriptor, path)


def put_prober(descriptor: dict, probe_env: dict) -> None:
    """bench/nodes/prober.py, with probe_env, in the place of the dataflow's keyboard_control node."""
    for node in descriptor["nodes"]:
        if node["id"] == "keyboard_control":
            node["path"] = str(PROBER)
            node["env"] = probe_env
            # The prompt keeps only the latest state; the prober counts every one.
            node["inputs"] = {name: {**spec, "queue_size": 1000} for name, spec in node["inputs"].items()}


def peak_rss_mb(pid: int | None) -> float | None:
    if pid is None:
        return None
    with contextlib.suppress(OSError):
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return None


def run_dataflow(run_dir: Path, duration_s: float, sim_env: dict, probe_env: dict, display: str | None = None,
                 body: str = "pybullet", extend: Callable[[dict], None] | None = None,
                 during: Callable[[float], None] | None = None) -> dict:
    """`dora run` for duration_s after the first joint_state, then Ctrl-C; the raw records.

    With `display` the nodes get that DISPLAY, and the measured time starts once the
    window shows the arm (it loads for a few seconds while the physics already runs);
    without, no DISPLAY (headless). `during(duration_s)`, when given, is called in place of
    sleeping through the measured time (bench/leader_bench.py moves the emulated leader in it;
    the dataflow runs until it returns)."""
    run_dir.mkdir(parents=True)
    tick_log = run_dir / "ticks.bin"
    probe_log = run_dir / "probe.json"
    dataflow = run_dir / "dataflow.yml"
    bench_dataflow(dataflow, {**sim_env, "SO101_TICK_LOG": str(tick_log)}, {**probe_env, "PROBE_LOG": str(probe_log)}, body,
                   extend)
    env = env_with_bin_first()
    env.pop("DISPLAY", None)
    if display:
        env["DISPLAY"] = display
    dora = dora_executable()
    if dora is None:
        raise RuntimeError("the dora CLI is not on PATH: pip install 'dora-rs-cli==1.1.0'")
    log_path = run_dir / "dora.log"
    with log_path.open("wb") as log:
        started_epoch_s = time.time()
        started_ns = time.monotonic_ns()
        process = subprocess.Popen(
            [dora, "run", str(dataflow), "--stop-after", f"{duration_s + 120:g}s"],
            cwd=run_dir, stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True,
        )
        try:
            deadline = time.monotonic() + 60
            while FIRST_STATE_MARK not in log_path.read_text(errors="replace"):
                if process.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"no joint_state from `dora run` (see {log_path}):\n{log_path.read_text(errors='replace')[-2000:]}")
                time.sleep(0.05)
            measured_from_ns = time.monotonic_ns()
            if display:
                while WINDOW_SHOWING not in log_path.read_text(errors="replace"):
                    if process.poll() is not None or time.monotonic() > deadline:
                        raise RuntimeError(f"the window did not show the arm (see {log_path})")
                    time.sleep(0.05)
                measured_from_ns = time.monotonic_ns()
            (during or time.sleep)(duration_s)
            simulation = processes_with_env("SO101_TICK_LOG", str(tick_log))
            rss_mb = peak_rss_mb(simulation[0] if simulation else None)
        finally:
            # Ctrl-C for dora (the nodes write their records on the way out); what is left is killed.
            stop_process(process, 30, kill_session=True)
    if not tick_log.exists() or not probe_log.exists():
        raise RuntimeError(f"`dora run` stopped without the nodes' records (see {log_path})")
    node_logs = sorted(run_dir.glob(f"out/*/log_{BODIES[body].node_id}.jsonl"))
    return {
        "started_ns": started_ns, "started_epoch_s": started_epoch_s, "ticks": tick_records(tick_log.read_bytes()),
        "probe": json.loads(probe_log.read_text()), "log": log_path.read_text(errors="replace"),
        "simulation_log": node_logs[-1].read_text(errors="replace") if node_logs else "",
        "peak_rss_mb": rss_mb, "exit_code": process.returncode, "measured_from_ns": measured_from_ns,
    }


def realtime_figures(record: dict, period_s: float) -> dict:
    """Figures 3-7 from one paced run's records, the first WARMUP_S after the first state left out of the rates."""
    probe = record["probe"]
    states = probe["states"]
    steady_from_ns = max(states[0][0], record["measured_from_ns"]) + int(WARMUP_S * 1e9)
    steady_ticks = [tick for tick in record["ticks"] if tick[0] >= steady_from_ns]
    ticks = tick_figures(steady_ticks, period_s)
    per_s, span_s = states_per_s(states, steady_from_ns)
    commands = probe["commands"]
    tick_starts_ns = [start for start, _, _ in record["ticks"]]
    latency = latency_breakdown(reflecting_states(states, commands, probe["probed_joints"]), tick_starts_ns)
    visible = latency_breakdown(reflecting_states(states, commands, probe["probed_joints"], VISIBLE_MOVE_DEG), tick_starts_ns)
    startup_s = (probe["first_state_ns"] - record["started_ns"]) / 1e9
    warnings_before, warnings_after = dropped_tick_warnings(record["simulation_log"], record["started_epoch_s"] + startup_s)
    return {
        "dataflow": {
            "measured_s": span_s,
            "joint_state_per_s": per_s,
            "expected_per_s": 1.0 / period_s,
            "ticks_missed": ticks["ticks_missed"],
            "ticks_served": ticks["ticks_served"],
            # Ticks discarded while the node loads the model (its Node() is up, so the timer runs).
            "dora_dropped_tick_warnings_startup": warnings_before,
            "dora_dropped_tick_warnings_steady": warnings_after,
            "tick_interval_ms": ticks["interval_ms"],
            "tick_work_us": ticks["work_us"],
            # Physics steps of the tick period over the wall time they took (the node's tick log).
            "sim_over_wall": ticks["steps_per_s"] * period_s,
            "startup_s": startup_s,
            "peak_rss_mb": record["peak_rss_mb"],
        },
        "command_latency_ms": {**latency, "probes_sent": len(commands),
                               "first_visible_move_ms": {key: visible[key] for key in ("p50", "p99", "mean", "max", "count")}},
    }
