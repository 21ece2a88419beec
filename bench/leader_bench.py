"""The leader arm's latency (`so101 bench`): the hand moves the leader; how soon the body shows it.

The leader is so101 fake-arm's emulated SO-101 (its pseudo-terminal bus served by a thread of
this process), calibrated as at the factory. The body's dataflow runs as `so101 teleop --leader`
runs it (so101.runtime.dataflow.with_leader: nodes/leader_node.py reads the leader every 10 ms
and sends its angles to the body), with bench/nodes/prober.py in the prompt's place only
recording the joint_state it receives: it sends no probes, for its joint_cmd is the leader's
typed_cmd, and a typed command would take over from the leader.

Once the leader node is ready and the body has settled on the leader's pose, this process moves
one leader joint by hand every MOVE_PERIOD_S (plus a random fraction of the leader's tick, so the
phase of its reads is sampled fairly): shoulder_pan and wrist_roll in turn (the prober's two
recorded joints), each to ±HAND_STEP_DEG/2 around the middle of its travel, so every move but a
joint's first is HAND_STEP_DEG the other way. time.monotonic_ns() is noted as the move is made
(CLOCK_MONOTONIC is shared by the processes, so it compares with the prober's arrival times).
The latency of a move is to the first joint_state that shows the joint moved toward the leader's
new angle by more than MOVED_THRESHOLD_DEG (bench/common.py reflecting_states): the leader's tick
and SYNC READ, dora's transit to the body, the body's tick, and its state's transit.
"""

from __future__ import annotations

import bisect
import random
import time
from pathlib import Path

from bench.common import MOVED_THRESHOLD_DEG, WARMUP_S, reflecting_states, run_dataflow, target_row
from so101.bodies.registry import BODIES
from so101.feetech.calibration import MOTOR_IDS, MOTOR_NAMES, DEG_PER_STEP, Calibration, save_calibration
from so101.feetech.fake_arm import FakeArmProcess, calibrate_as_at_the_factory
from so101.leader.command import leader_values
from so101.runtime.dataflow import LEADER_READY_MARKS, LEADER_TICK, timer_period_s, with_leader
from so101.stats import summary

MOVE_PERIOD_S = 0.3
HAND_STEP_DEG = 4.0
MOVED_JOINTS = (0, 4)  # shoulder_pan, wrist_roll: the joints the prober records
LEADER_TICK_S = timer_period_s({"inputs": {"tick": LEADER_TICK}}) or 0.01
READY_TIMEOUT_S = 60.0
# For comparison, in the table: LeRobot's leader -> follower loop on an SO-100, measured by its users.
# The issue asking for this row cites LeRobot issue #560 for 12-34 ms a loop; that thread could not be
# checked here, and a loop period is not a move-to-state latency: docs/loop/leader.md says both.
LEROBOT_NOTE = "LeRobot on an SO-100, as cited from its issue #560: 12-34 ms a teleoperation loop, a period, not this latency"


class Hand:
    """A person's hand on the emulated leader: a move every MOVE_PERIOD_S, each noted as
    [monotonic ns, joint, the leader's new angle in the follower's degrees]."""

    def __init__(self, arm: FakeArmProcess, calibration: Calibration, dora_log: Path):
        self.arm = arm
        self.motors = [calibration[name] for name in MOTOR_NAMES]
        self.dora_log = dora_log
        self.moves: list[list] = []

    def _wait_for_the_leader(self) -> None:
        deadline = time.monotonic() + READY_TIMEOUT_S
        while not any(mark in self.dora_log.read_text(errors="replace") for mark in LEADER_READY_MARKS):
            if time.monotonic() > deadline:
                raise RuntimeError(f"the leader node never said it was ready (see {self.dora_log})")
            time.sleep(0.05)

    def move(self, duration_s: float) -> None:
        """`duration_s` of moves, after the leader node is ready and the body has settled (run_dataflow's `during`)."""
        self._wait_for_the_leader()
        time.sleep(WARMUP_S)  # the body takes up the leader's pose at its first reading
        end = time.monotonic() + duration_s
        next_move = time.monotonic()
        made = 0
        while next_move < end:
            time.sleep(max(0.0, next_move - time.monotonic()))
            joint = MOVED_JOINTS[made % len(MOVED_JOINTS)]
            side = 1 if (made // len(MOVED_JOINTS)) % 2 == 0 else -1
            servo_id = MOTOR_IDS[joint]
            self.arm.move_by_hand(servo_id, round(self.arm.mechanics(servo_id).centre + side * HAND_STEP_DEG / 2 / DEG_PER_STEP))
            moved_ns = time.monotonic_ns()
            # What the leader node reads from now on, for this joint.
            target_deg = leader_values(joint, self.arm.read_register(servo_id, "Present_Position"), self.motors[joint])
            self.moves.append([moved_ns, joint, target_deg])
            made += 1
            next_move += MOVE_PERIOD_S + random.uniform(0.0, LEADER_TICK_S)
        time.sleep(MOVE_PERIOD_S)  # the last move reaches the body before the dataflow stops


def leader_latency(states: list, moves: list, joints: list[int], tick_starts_ns: list[int],
                   threshold_deg: float = MOVED_THRESHOLD_DEG) -> dict:
    """The hand's moves -> the first joint_state that shows each (ms): p50, p99, mean, max, count (the moves
    shown), `moves` (made), `each_move_ms` in order (None: not shown), and that time split at the start of
    the body's tick that published the state: the leader's tick, its read, the transit and the body's wait
    before; the body's tick and the state's transit after. states: the prober's [arrival ns, angle of
    joints[0], ...]; moves: Hand.moves; tick_starts_ns: the body's tick log's starts (the same clock)."""
    pairs = reflecting_states(states, moves, joints, threshold_deg)
    before, after = [], []
    for moved_ns, arrival_ns in pairs:
        serving = bisect.bisect_right(tick_starts_ns, arrival_ns) - 1
        if 0 <= serving and tick_starts_ns[serving] >= moved_ns:
            before.append((tick_starts_ns[serving] - moved_ns) / 1e6)
            after.append((arrival_ns - tick_starts_ns[serving]) / 1e6)
    shown = dict(pairs)
    each = [None if moved_ns not in shown else round((shown[moved_ns] - moved_ns) / 1e6, 3) for moved_ns, _, _ in moves]
    return {**summary([(arrival_ns - moved_ns) / 1e6 for moved_ns, arrival_ns in pairs]), "moves": len(moves),
            "to_the_body_tick_ms": summary(before), "body_tick_to_arrival_ms": summary(after),
            "each_move_ms": each}


def run_leader_benchmark(work_dir: Path, duration_s: float, body: str, body_env: dict) -> dict:
    """`body` (its node's settings in `body_env`) driven by an emulated leader for `duration_s` of moves."""
    run_dir = work_dir / "leader"
    with FakeArmProcess() as arm:
        calibration = calibrate_as_at_the_factory(arm)
        calibration_file = work_dir / "so101_leader.json"
        save_calibration(calibration_file, calibration)
        leader_env = {"SO101_LEADER_PORT": arm.port, "SO101_LEADER_CALIBRATION": str(calibration_file), "SO101_LANG": "en"}
        hand = Hand(arm, calibration, run_dir / "dora.log")

        def add_leader(descriptor: dict) -> None:
            with_leader(descriptor, BODIES[body].node_id, leader_env)

        print(f"dora run with the emulated leader ({arm.port}) driving the body, a move every {MOVE_PERIOD_S:g} s "
              f"for {duration_s:g} s ...", flush=True)
        record = run_dataflow(run_dir, duration_s, body_env, {"PROBE_PERIOD_S": "0"}, body=body,
                              extend=add_leader, during=hand.move)
    probe = record["probe"]
    figures = leader_latency(probe["states"], hand.moves, probe["probed_joints"], [start for start, _, _ in record["ticks"]])
    return {"latency_ms": figures, "move_period_s": MOVE_PERIOD_S, "hand_step_deg": HAND_STEP_DEG,
            "leader_tick_ms": LEADER_TICK_S * 1e3}


def target(figures: dict, p99_ms: float, to: str) -> dict:
    """The targets row: the leader's move -> joint_state, p99, at most p99_ms."""
    p99 = figures["latency_ms"]["p99"]
    return target_row(f"leader -> joint_state latency p99, {to} (ms)", p99, f"<= {p99_ms:g}", p99 <= p99_ms)


def table_lines(figures: dict, label_width: int = 52, value_width: int = 0) -> list[str]:
    """The table's leader rows: run_bench's layout (the first value right-aligned in 10), or with
    `value_width` the values right-aligned in a column that wide (real_bench's)."""
    latency = figures["latency_ms"]
    first = 0 if value_width else 10

    def row(label: str, value: str) -> str:
        return f"{label:<{label_width}} {value:>{value_width}}".rstrip()

    return [
        row("leader moved -> joint_state (ms, p50 | p99 | max)",
            f"{latency['p50']:>{first}.2f} | {latency['p99']:.2f} | {latency['max']:.2f}"),
        row("  split at the body's tick: before | after (ms, p99)",
            f"{latency['to_the_body_tick_ms']['p99']:>{first}.2f} | {latency['body_tick_to_arrival_ms']['p99']:.2f}"),
        row("  moves the body showed / moves made", f"{latency['count']:>{first}d} / {latency['moves']}"),
        f"  ({LEROBOT_NOTE})",
    ]
