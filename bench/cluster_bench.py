"""`so101 bench --cluster`: the simulation across two dora daemons on 127.0.0.1, next to one.

The same measurement twice, back to back: dataflow.yml under `dora run` (one daemon), then
dataflow_cluster.yml on a coordinator and two daemons (so101/runtime/cluster.py), the simulation on
daemon `arm` and bench/nodes/prober.py, in the prompt's place, on daemon `desk`, so every
joint_cmd and joint_state crosses between the daemons over Zenoh. Figures: joint_state per
second at the prober against the tick's 250, and the joint_cmd -> joint_state latency (the
first state that moved toward the probe) p50/p99. Loopback: no network in between, so these
are dora's and Zenoh's own costs, not a network's.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from pathlib import Path

import yaml

from bench.common import (
    FIRST_STATE_MARK, PACED_PROBE_ENV, WARMUP_S, machine_facts, machine_line, put_prober, realtime_figures, run_dataflow,
    tick_records,
)
from so101.bodies.registry import BODIES, DEFAULT_BODY
from so101.runtime.cluster import BODY_MACHINE, PROMPT_MACHINE, Cluster, cluster_dataflow
from so101.runtime.dataflow import TICK_PERIOD_S


def _cluster_record(work_dir: Path, duration_s: float) -> dict:
    """The cluster run's records, in the form bench.common.realtime_figures reads."""
    tick_log, probe_log = work_dir / "ticks.bin", work_dir / "probe.json"
    cluster = Cluster(work_dir / "cluster")
    try:
        started_epoch_s, started_ns = time.time(), time.monotonic_ns()
        cluster.start_coordinator()
        cluster.start_daemon(BODY_MACHINE)
        cluster.start_daemon(PROMPT_MACHINE)
        dataflow = cluster_dataflow(work_dir, {"SO101_MODE": "direct", "SO101_LANG": "en", "SO101_TICK_LOG": str(tick_log)},
                                    BODIES[DEFAULT_BODY])
        descriptor = yaml.safe_load(dataflow.read_text())
        put_prober(descriptor, {**PACED_PROBE_ENV, "PROBE_LOG": str(probe_log)})  # spawned by daemon `desk`
        dataflow.write_text(yaml.safe_dump(descriptor, sort_keys=False))
        cluster.start_dataflow(dataflow)
        deadline = time.monotonic() + 60
        while FIRST_STATE_MARK not in cluster.node_log(PROMPT_MACHINE, "keyboard_control"):
            if time.monotonic() > deadline:
                raise RuntimeError("no joint_state reached the prober on daemon `desk` within 60 s")
            time.sleep(0.05)
        measured_from_ns = time.monotonic_ns()
        time.sleep(duration_s + WARMUP_S)
        cluster.cli("stop", "--name", "so101", timeout_s=30)
        deadline = time.monotonic() + 20
        while not (tick_log.exists() and probe_log.exists()) and time.monotonic() < deadline:
            time.sleep(0.1)
    finally:
        cluster.stop()
    if not (tick_log.exists() and probe_log.exists()):
        raise RuntimeError(f"the cluster run stopped without the nodes' records (see {work_dir})")
    return {
        "started_ns": started_ns, "started_epoch_s": started_epoch_s, "ticks": tick_records(tick_log.read_bytes()),
        "probe": json.loads(probe_log.read_text()), "measured_from_ns": measured_from_ns,
        "simulation_log": cluster.node_log(BODY_MACHINE, "simulation"), "peak_rss_mb": None,
    }


def run_cluster_benchmark(duration_s: float) -> dict:
    load_start = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="so101-bench-cluster-") as tmp:
        work_dir = Path(tmp)
        print(f"dora run dataflow.yml (one daemon), {duration_s:g} s ...", flush=True)
        single = realtime_figures(run_dataflow(work_dir / "single", duration_s + WARMUP_S, {"SO101_FAST_STEPS": "0"},
                                               PACED_PROBE_ENV), TICK_PERIOD_S)
        print(f"dataflow_cluster.yml on two daemons (arm, desk) on 127.0.0.1, {duration_s:g} s ...", flush=True)
        (work_dir / "cluster").mkdir()
        across = realtime_figures(_cluster_record(work_dir / "cluster", duration_s), TICK_PERIOD_S)

    def keep(figures: dict) -> dict:
        latency = figures["command_latency_ms"]
        return {"joint_state_per_s": figures["dataflow"]["joint_state_per_s"], "ticks_missed": figures["dataflow"]["ticks_missed"],
                "latency_ms": {key: latency[key] for key in ("p50", "p99", "max", "count")}}

    return {
        "body": "cluster",
        "machine": machine_facts(),
        "load_average_1_5_15min": {"start": list(load_start), "end": list(os.getloadavg())},
        "settings": {"tick_ms": TICK_PERIOD_S * 1e3, "duration_s": duration_s, "warmup_s": WARMUP_S},
        "one_daemon": keep(single),
        "two_daemons": keep(across),
    }


def table(result: dict) -> str:
    machine, one, two = result["machine"], result["one_daemon"], result["two_daemons"]

    def ms(latency: dict) -> str:
        return f"{latency['p50']:.2f} | {latency['p99']:.2f}"

    return "\n".join([
        f"SO-101 across dora daemons on 127.0.0.1 (loopback, not a network), {machine['date']}",
        machine_line(result),
        "",
        f"{'figure':<48} {'one daemon':>14} {'two daemons':>14}",
        f"{'joint_state per s at the prompt (against 250)':<48} {one['joint_state_per_s']:>14.1f} {two['joint_state_per_s']:>14.1f}",
        f"{'ticks missed':<48} {one['ticks_missed']:>14} {two['ticks_missed']:>14}",
        f"{'joint_cmd -> joint_state latency (ms, p50 | p99)':<48} {ms(one['latency_ms']):>14} {ms(two['latency_ms']):>14}",
    ])
