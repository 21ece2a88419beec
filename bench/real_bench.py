"""`so101 bench --body real`: the real arm's driver against `so101 fake-arm`'s emulated bus.

One run measures:
  1. the bus round trip: one SYNC READ of the six Present_Positions (request out, six
     replies in), and a whole tick's exchange (the SYNC WRITE of the goals, then that read),
     in process, through SO101Real as the node uses it;
  2. dataflow_real.yml under a real headless `dora run`, with bench/nodes/prober.py in the
     place of keyboard_control: joint_state/s against the 50 Hz tick, ticks missed, per-tick
     work, the joint_cmd -> joint_state latency (the first state that moved), start-up;
  3. the same dataflow driven by a second emulated arm as the leader (bench/leader_bench.py): the
     leader moved by hand -> the first joint_state that shows it.
What it does not measure: a real adapter. The emulator answers over a pseudo-terminal in
a fraction of a millisecond; a USB serial adapter adds its latency timer to every read
(1-16 ms, see dataflow_real.yml), and real servos add their return delay.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

from bench import leader_bench
from bench.common import (
    PROBE_STEP_DEG, WARMUP_S, latency_breakdown, machine_facts, machine_line, reflecting_states, run_dataflow, target_lines,
    states_per_s, target_row, tick_figures,
)
from so101.bodies.real_arm import SO101Real
from so101.feetech.calibration import save_calibration
from so101.feetech.fake_arm import FakeArmProcess, calibrate_as_at_the_factory
from so101.stats import summary

TICK_S = 0.02  # dataflow_real.yml's timer
TARGETS = {
    "joint_state_per_s": 49.5,  # 99% of 50, at least
    "round_trip_p99_ms": TICK_S * 1e3 / 2,  # the read must leave half the tick free, at most
    # The goal goes out on the next tick; the servo has barely begun to move when that tick reads
    # it back, so the move shows on the tick after: two ticks, and the transit, at most.
    "latency_p99_ms": 2 * TICK_S * 1e3 + 5,
    "startup_s": 3.0,
    # The leader moved by hand -> the follower's joint_state showing it, p99, at most: the leader's
    # 10 ms tick and read, then the command latency's two follower ticks and the transits.
    "leader_latency_p99_ms": 45.0,
}
PROBE_PERIOD_S = "0.3"  # a 4° probe at 90°/s takes 45 ms: each probe is done before the next


def measure_bus(arm: FakeArmProcess, calibration, exchanges: int) -> dict:
    body = SO101Real(arm.port, calibration, time_step_s=TICK_S)
    try:
        body.round_trips_s = type(body.round_trips_s)("d")
        tick_s = []
        for number in range(exchanges):
            body.set_targets_deg([10.0 if number % 100 < 50 else -10.0, 0, 0, 0, 0, 45])
            start = time.perf_counter()
            body.step()
            tick_s.append(time.perf_counter() - start)
        return {"sync_read_ms": summary(body.round_trips_s, 1e3), "tick_exchange_ms": summary(tick_s, 1e3)}
    finally:
        body.close()


def run_real_benchmark(duration_s: float, exchanges: int) -> dict:
    load_start = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="so101-bench-real-") as tmp, FakeArmProcess() as arm:
        work_dir = Path(tmp)
        calibration = calibrate_as_at_the_factory(arm)
        calibration_file = work_dir / "so101_follower.json"
        save_calibration(calibration_file, calibration)
        print(f"body: real, on so101 fake-arm's emulated bus {arm.port}; {exchanges} bus exchanges in process ...", flush=True)
        bus = measure_bus(arm, calibration, exchanges)
        print(f"dora run dataflow_real.yml, paced by the 20 ms tick, {duration_s:g} s ...", flush=True)
        record = run_dataflow(
            work_dir / "paced", duration_s + WARMUP_S,
            {"SO101_PORT": arm.port, "SO101_CALIBRATION": str(calibration_file)},
            {"PROBE_PERIOD_S": PROBE_PERIOD_S, "PROBE_STEP_DEG": PROBE_STEP_DEG, "PROBE_PHASE_S": str(TICK_S)}, body="real",
        )
        leader = leader_bench.run_leader_benchmark(
            work_dir, duration_s, "real", {"SO101_PORT": arm.port, "SO101_CALIBRATION": str(calibration_file)})
    probe = record["probe"]
    states = probe["states"]
    steady_from_ns = max(states[0][0], record["measured_from_ns"]) + int(WARMUP_S * 1e9)
    ticks = tick_figures([tick for tick in record["ticks"] if tick[0] >= steady_from_ns], TICK_S)
    per_s, span_s = states_per_s(states, steady_from_ns)
    latency = latency_breakdown(reflecting_states(states, probe["commands"], probe["probed_joints"]),
                                [start for start, _, _ in record["ticks"]])
    dataflow = {
        "measured_s": span_s,
        "joint_state_per_s": per_s,
        "expected_per_s": 1 / TICK_S,
        "ticks_served": ticks["ticks_served"],
        "ticks_missed": ticks["ticks_missed"],
        "tick_interval_ms": ticks["interval_ms"],
        "tick_work_ms": summary([(end - start) / 1e6 for start, end, _ in record["ticks"]]),
        "startup_s": (probe["first_state_ns"] - record["started_ns"]) / 1e9,
    }
    figures = {"bus": bus, "dataflow": dataflow, "command_latency_ms": {**latency, "probes_sent": len(probe["commands"])},
               "leader": leader}
    figures["targets"] = [
        target_row(name, value, target, met) for name, value, target, met in (
            ("joint_state per s (dora run)", dataflow["joint_state_per_s"], f">= {TARGETS['joint_state_per_s']}",
             dataflow["joint_state_per_s"] >= TARGETS["joint_state_per_s"]),
            ("bus round trip p99 (ms)", bus["sync_read_ms"]["p99"], f"<= {TARGETS['round_trip_p99_ms']:g}",
             bus["sync_read_ms"]["p99"] <= TARGETS["round_trip_p99_ms"]),
            ("command latency p99 (ms)", latency["p99"], f"<= {TARGETS['latency_p99_ms']:g}", latency["p99"] <= TARGETS["latency_p99_ms"]),
            ("start-up to first joint_state (s)", dataflow["startup_s"], f"<= {TARGETS['startup_s']:g}",
             dataflow["startup_s"] <= TARGETS["startup_s"]),
        )
    ] + [leader_bench.target(leader, TARGETS["leader_latency_p99_ms"], "emulated follower")]
    return {
        "body": "real",
        "machine": machine_facts(),
        "load_average_1_5_15min": {"start": list(load_start), "end": list(os.getloadavg())},
        "settings": {"tick_ms": TICK_S * 1e3, "duration_s": duration_s, "exchanges": exchanges, "warmup_s": WARMUP_S,
                     "bus": "so101 fake-arm (emulated, pseudo-terminal)"},
        **figures,
    }


def table(result: dict) -> str:
    machine, bus, flow, latency = result["machine"], result["bus"], result["dataflow"], result["command_latency_ms"]

    def ms(figures: dict) -> str:
        return f"{figures['p50']:.2f} | {figures['p99']:.2f} | {figures['max']:.2f}"

    lines = [
        f"SO-101 real-arm driver benchmark, on so101 fake-arm's emulated bus (not a USB adapter), {machine['date']}",
        machine_line(result),
        "",
        f"{'figure':<66} {'value':>22}",
        f"{'bus round trip, SYNC READ of 6 positions (ms, p50 | p99 | max)':<66} {ms(bus['sync_read_ms']):>22}",
        f"{'one tick on the bus, SYNC WRITE + SYNC READ (ms, p50 | p99 | max)':<66} {ms(bus['tick_exchange_ms']):>22}",
        f"{'joint_state per s (dora run, against 50)':<66} {flow['joint_state_per_s']:>22.2f}",
        f"{'ticks missed / served':<66} {flow['ticks_missed']:>10} / {flow['ticks_served']:<9}",
        f"{'tick interval (ms, p50 | p99 | max)':<66} {ms(flow['tick_interval_ms']):>22}",
        f"{'node work per tick (ms, p50 | p99 | max)':<66} {ms(flow['tick_work_ms']):>22}",
        f"{'joint_cmd -> joint_state latency (ms, p50 | p99 | max)':<66} {ms(latency):>22}",
        f"{'start-up to first joint_state (s)':<66} {flow['startup_s']:>22.2f}",
    ]
    if "leader" in result:  # results from before the leader arm have no leader rows
        lines += leader_bench.table_lines(result["leader"], 66, 22)
    lines += ["", *target_lines(result["targets"])]
    return "\n".join(lines)
