"""The benchmark (`so101 bench`): its analysis, the node's fast mode and tick log, and a smoke run.

No speed targets are asserted here: they are the benchmark's output, not tests.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import sys
from array import array
from pathlib import Path

import pyarrow as pa
import pytest

from so101.bodies import node_loop as body_node
from bench import camera_bench, common, leader_bench, real_bench, run_bench, web_bench
from tests.helpers.dataflow import TICK, run_simulation_node

MS = 1_000_000  # ns


# -- analysis (the percentiles: tests/test_stats.py) --------------------------------------
def test_tick_figures_count_missed_ticks_from_the_gaps():
    starts_ms = [0, 4, 8, 20, 24, 28.7, 32]  # 8 -> 20 ms: the ticks at 12 and 16 were dropped
    steps = [1, 2, 3, 6, 7, 8, 9]  # and the tick at 20 ms took their steps
    ticks = [(int(start * MS), int(start * MS) + 30_000, count) for start, count in zip(starts_ms, steps)]
    figures = common.tick_figures(ticks, 0.004)
    assert figures["ticks_served"] == 7
    assert figures["ticks_missed"] == 2
    assert figures["steps_per_s"] == pytest.approx(8 / 0.032)  # 8 steps from the first tick's end to the last's
    assert figures["interval_ms"]["p50"] == pytest.approx(4.0, abs=0.01)
    assert figures["interval_ms"]["max"] == pytest.approx(12.0)
    assert figures["work_us"]["p50"] == pytest.approx(30.0)


def test_tick_log_bytes_become_start_end_steps_records():
    raw = array("q", [10, 15, 1, 20, 26, 3]).tobytes()
    assert common.tick_records(raw) == [(10, 15, 1), (20, 26, 3)]
    assert common.tick_records(raw + b"\x01\x02") == [(10, 15, 1), (20, 26, 3)]  # a torn write is ignored


def test_states_per_s_counts_by_sending_so_a_stalled_prober_does_not_make_a_burst_a_rate():
    # Sent every 4 ms for 2 s; the prober stalled and took the first 0.8 s of them at 0.8 s at once.
    sent_ms = [4 * k for k in range(501)]
    states = [[max(t, 800) * MS, 0.0, 0.0, t * MS] for t in sent_ms]
    assert common.states_per_s(states, 0) == pytest.approx((250.0, 2.0))
    assert common.states_per_s(states, 1000 * MS) == pytest.approx((250.0, 1.0))
    assert common.states_per_s(states, 0, 400 * MS) == pytest.approx((250.0, 0.4))
    # Every other state lost: half the rate.
    assert common.states_per_s(states[::2], 0)[0] == pytest.approx(125.0)


def test_latency_is_send_to_first_state_moving_toward_the_target():
    # States every 4 ms; joint 0 rests at 0.0 until the state at 16 ms shows +0.07°.
    states = [[t * MS, 0.0, 0.0] for t in (0, 4, 8, 12)] + [[16 * MS, 0.07, 0.0], [20 * MS, 0.3, 0.0]]
    commands = [[5 * MS, 0, 2.0]]
    pairs = common.reflecting_states(states, commands, [0, 4])
    assert pairs == [(5 * MS, 16 * MS)]
    # Ticks start 0.3 ms before each state arrives; the first tick after the send (7.7 ms)
    # did not carry the command, the one at 15.7 ms did.
    tick_starts = [int((t - 0.3) * MS) for t in (4, 8, 12, 16, 20)]
    breakdown = common.latency_breakdown(pairs, tick_starts)
    assert breakdown["p50"] == pytest.approx(11.0)
    assert breakdown["wait_for_next_tick_ms"]["p50"] == pytest.approx(2.7)
    assert breakdown["tick_start_to_arrival_ms"]["p50"] == pytest.approx(0.3)
    assert breakdown["probes_that_missed_the_next_tick"] == 1


def test_a_visible_move_is_the_first_state_past_the_visible_threshold():
    states = [[0, 0.0, 0.0], [4 * MS, 0.07, 0.0], [8 * MS, 0.3, 0.0], [12 * MS, 0.5, 0.0]]
    commands = [[1 * MS, 0, 4.0]]
    assert common.reflecting_states(states, commands, [0, 4]) == [(1 * MS, 4 * MS)]
    assert common.reflecting_states(states, commands, [0, 4], common.VISIBLE_MOVE_DEG) == [(1 * MS, 12 * MS)]


def test_motion_away_from_the_target_does_not_count():
    states = [[0, 0.0, 0.0], [4 * MS, -0.5, 0.0], [8 * MS, 0.2, 0.0]]
    assert common.reflecting_states(states, [[1 * MS, 0, 2.0]], [0, 4]) == [(1 * MS, 8 * MS)]
    assert common.reflecting_states(states, [[1 * MS, 4, 2.0]], [0, 4]) == []  # joint 4 never moved


def test_dropped_tick_warnings_split_at_the_first_state():
    def line(ts, level="warn", msg="Discarding event for input `tick` due to queue size limit"):
        return json.dumps({"ts": ts, "level": level, "node": "simulation", "msg": msg})

    jsonl = "\n".join([
        line("2026-01-01T00:00:01.000Z"), line("2026-01-01T00:00:01.500Z"),
        line("2026-01-01T00:00:03.000Z"), line("2026-01-01T00:00:03.000Z", level="stdout", msg="loaded"),
        "not json",
    ])
    first_state = 1767225602.0  # 2026-01-01T00:00:02Z
    assert common.dropped_tick_warnings(jsonl, first_state) == (2, 1)


def test_leader_latency_is_the_move_to_the_first_state_showing_it_split_at_the_bodys_tick():
    # States every 4 ms (their ticks start 0.5 ms before); joint 4 shows the move at 16 ms, joint 0's
    # later move away from the hand's new angle does not count, then the move toward it at 40 ms does.
    states = [[t * MS, 0.0, 0.0] for t in (0, 4, 8, 12)] + [[16 * MS, 0.0, 0.1], [20 * MS, 0.0, 0.5],
                                                           [24 * MS, 0.0, 0.5], [28 * MS, -0.2, 0.5], [40 * MS, 0.3, 0.5]]
    moves = [[5 * MS, 4, 2.0], [22 * MS, 0, 2.0], [41 * MS, 4, -2.0]]  # the last: the run ended first
    tick_starts = [int((t - 0.5) * MS) for t in (4, 8, 12, 16, 20, 24, 28, 40)]
    figures = leader_bench.leader_latency(states, moves, [0, 4], tick_starts)
    assert figures["count"] == 2 and figures["moves"] == 3
    assert figures["max"] == pytest.approx(18.0)  # 22 -> 40 ms
    assert figures["p50"] == pytest.approx((11.0 + 18.0) / 2)
    assert figures["to_the_body_tick_ms"]["max"] == pytest.approx(17.5)
    assert figures["body_tick_to_arrival_ms"]["p50"] == pytest.approx(0.5)


def test_the_hand_moves_each_leader_joint_a_few_degrees_each_way_in_turn(tmp_path, monkeypatch):
    from so101.feetech.fake_arm import FakeArmProcess, calibrate_as_at_the_factory
    from so101.runtime.dataflow import LEADER_READY_MARKS

    monkeypatch.setattr(leader_bench, "WARMUP_S", 0.0)
    monkeypatch.setattr(leader_bench, "MOVE_PERIOD_S", 0.01)
    monkeypatch.setattr(leader_bench, "LEADER_TICK_S", 0.0)
    dora_log = tmp_path / "dora.log"
    dora_log.write_text(f"[leader] {LEADER_READY_MARKS[0]}, /dev/pts/9\n")
    with FakeArmProcess() as arm:
        hand = leader_bench.Hand(arm, calibrate_as_at_the_factory(arm), dora_log)
        hand.move(0.035)  # a move at 0, 10, 20 and 30 ms of the 35 asked for, however late each comes
    half = leader_bench.HAND_STEP_DEG / 2
    assert [joint for _, joint, _ in hand.moves] == [0, 4, 0, 4]
    assert [target for _, _, target in hand.moves] == pytest.approx([half, half, -half, -half], abs=0.1)
    assert all(a[0] < b[0] for a, b in zip(hand.moves, hand.moves[1:]))


# -- the node's fast mode and tick log ---------------------------------------------------
def test_fast_events_make_up_a_tick_whenever_nothing_waits():
    command = {"type": "INPUT", "id": "joint_cmd", "value": pa.array([0, 10])}
    stop = {"type": "STOP"}

    class Queue:
        replies = [None, None, command, None, stop]

        def try_recv(self):
            return self.replies.pop(0)

    events = body_node.fast_events(Queue())
    got = [next(events) for _ in range(5)]
    assert got == [body_node.FAST_TICK, body_node.FAST_TICK, command, body_node.FAST_TICK, stop]


def test_fast_mode_takes_n_steps_per_published_state(monkeypatch):
    # 4 ticks of 100 steps each are 1.6 s of simulated time: enough to reach 45°.
    # Paced, 4 ticks are 16 ms and the joint has barely started.
    events = [("joint_cmd", pa.array([0, 45]))] + [TICK] * 4
    code, node = run_simulation_node(monkeypatch, events, SO101_FAST_STEPS="100")
    assert code == 0
    assert len(node.outputs["joint_state"]) == 4
    assert node.outputs["joint_state"][-1].to_pylist()[0] == pytest.approx(45.0, abs=1.0)
    code, node = run_simulation_node(monkeypatch, events, SO101_FAST_STEPS="0")
    assert node.outputs["joint_state"][-1].to_pylist()[0] < 5.0


@pytest.mark.parametrize("value", ["-1", "2.5", "fast", ""])
def test_bad_fast_steps_gives_one_line_and_exit_2(monkeypatch, capsys, value):
    code, _ = run_simulation_node(monkeypatch, [TICK], SO101_FAST_STEPS=value)
    assert code == 2
    assert f"SO101_FAST_STEPS={value!r} is not a whole number >= 0" in capsys.readouterr().err


def test_tick_log_holds_start_and_end_of_each_tick(monkeypatch, tmp_path):
    tick_log = tmp_path / "ticks.bin"
    events = [TICK] * 30 + [("joint_cmd", pa.array([0, 10]))]
    code, node = run_simulation_node(monkeypatch, events, SO101_TICK_LOG=str(tick_log))
    assert code == 0
    records = common.tick_records(tick_log.read_bytes())
    assert len(records) == 30  # one per tick, none for the joint_cmd
    assert all(start < end for start, end, _ in records)
    assert all(end <= next_start for (_, end, _), (next_start, _, _) in zip(records, records[1:]))
    assert [steps for _, _, steps in records] == list(range(1, 31))  # a mock's ticks carry no timestamp: one step each


def test_without_tick_log_no_file_is_written(monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    code, _ = run_simulation_node(monkeypatch, [TICK] * 3, SO101_TICK_LOG="")
    assert code == 0 and list(tmp_path.iterdir()) == []


# -- the command -------------------------------------------------------------------------
def test_bad_duration_gives_one_line_and_exit_2():
    so101 = Path(sys.executable).parent / "so101"
    result = subprocess.run([str(so101), "bench", "--duration", "0"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert "'0' is not a number of seconds above 0 and at most 3600" in result.stderr


def _positive(value):
    return isinstance(value, (int, float)) and math.isfinite(value) and value > 0


@pytest.mark.dataflow
@pytest.mark.alone  # a benchmark loads the whole machine
@pytest.mark.parametrize("body", ["pybullet"])  # MuJoCo's node runs the same bench code: one body keeps the suite's budget
def test_quick_bench_writes_every_figure(tmp_path, body):
    out = tmp_path / "bench.json"
    so101 = Path(sys.executable).parent / "so101"
    result = subprocess.run(
        [str(so101), "bench", "--quick", "--body", body, "--out", str(out)], capture_output=True, text=True, timeout=300,
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    assert f"wrote {out}" in result.stdout
    figures = json.loads(out.read_text())
    assert figures["body"] == body
    assert f"SO-101 simulation node benchmark ({body})" in result.stdout

    machine = figures["machine"]
    assert machine["cores"] >= 1 and machine["cpu"] and machine["python"].startswith("3.11")
    assert machine["dora_rs"] == "1.1.0" and machine["pybullet"] == "3.2.7" and machine["date"]
    assert len(figures["load_average_1_5_15min"]["start"]) == 3

    raw = figures["raw_step"]
    assert 1 < raw["us_per_step_p50"] < 10_000 and raw["us_per_step_p99"] >= raw["us_per_step_p50"]
    assert _positive(raw["steps_per_s"]) and _positive(raw["after_4ms_sleep_us_p50"])

    work = figures["node_work_in_process"]
    assert work["p99"] >= work["p50"] > 0 and _positive(work["ratio_to_raw_p50"])

    flow = figures["dataflow"]
    assert 100 < flow["joint_state_per_s"] < 300  # a 4 ms timer: 250 when served in full
    assert flow["expected_per_s"] == pytest.approx(250.0)
    assert flow["ticks_missed"] >= 0 and flow["ticks_served"] > 300
    assert flow["tick_interval_ms"]["p99"] >= flow["tick_interval_ms"]["p50"] > 0
    assert flow["tick_work_us"]["p99"] >= flow["tick_work_us"]["p50"] > 0
    assert 0.4 < flow["sim_over_wall"] < 1.2
    assert 0 < flow["startup_s"] < 60
    assert 30 < flow["peak_rss_mb"] < 4000
    assert flow["dora_dropped_tick_warnings_startup"] >= 0 and flow["dora_dropped_tick_warnings_steady"] >= 0

    latency = figures["command_latency_ms"]
    assert latency["count"] >= 10 and latency["probes_sent"] >= latency["count"]
    assert latency["p99"] >= latency["p50"] > 0
    assert latency["wait_for_next_tick_ms"]["p50"] >= 0
    visible = latency["first_visible_move_ms"]
    assert visible["count"] >= 10 and visible["p50"] >= latency["p50"]

    gui = figures["gui"]
    if shutil.which("Xvfb") is None and not os.environ.get("DISPLAY"):
        assert gui["skipped"] == "Xvfb is not installed (Debian package xvfb)"
        window_rows = 0
    else:
        assert 100 < gui["joint_state_per_s"] < 300 and 0.4 < gui["sim_over_wall"] < 1.2
        assert gui["latency_ms"]["p99"] >= gui["latency_ms"]["p50"] > 0 and gui["first_visible_move_ms"]["count"] >= 10
        assert "window open" in result.stdout
        window_rows = 2

    runs = figures["fast_mode"]["runs"]
    assert [run["steps_per_state"] for run in runs] == [1, 100]
    for run in runs:
        assert _positive(run["steps_per_s"]) and _positive(run["ratio_to_raw"])
        # The ratio is against the raw step taken beside the run, not at the bench's start.
        beside_us = (run["raw_step_us_p50"]["before"] + run["raw_step_us_p50"]["after"]) / 2
        assert run["ratio_to_raw"] == pytest.approx(beside_us * run["steps_per_s"] / 1e6)
    # Fewer publications per step can only help: 100 steps per state beat 1.
    assert runs[1]["steps_per_s"] > runs[0]["steps_per_s"]

    recording = figures["recording"]
    assert recording["picture_ms"]["p99"] >= recording["picture_ms"]["p50"] > 0
    while_recording = recording["recording"]
    assert 100 < while_recording["joint_state_per_s"] < 300 and 0.4 < while_recording["sim_over_wall"] < 1.2
    # Why pictures are drawn by a node of their own: inside the physics loop they hold it back.
    assert 0 < recording["pictures_in_loop"]["joint_state_per_s"] < while_recording["joint_state_per_s"]
    # The episode recorded the whole run at 30 frames per wall-clock second, with new pictures in it.
    assert while_recording["frames"] > 60 and 25 < while_recording["frames_per_wall_s"] < 35
    assert while_recording["new_pictures_per_s"] > 0
    saving = recording["saving"]
    assert saving["episode_s"] == 5 and saving["frames"] == 150 and 0 < saving["save_s"] < 60
    assert "recording with video: joint_state per s" in result.stdout
    recording_rows = 2  # the 60 s save's target is judged in full runs only

    leader = figures["leader"]["latency_ms"]
    # The hand moved every 0.3 s for the 3 s run; the body showed (nearly) every move.
    assert leader["moves"] >= 8 and leader["count"] >= leader["moves"] - 1
    assert leader["max"] >= leader["p99"] >= leader["p50"] > 0
    assert "leader moved -> joint_state" in result.stdout
    leader_rows = 1

    web = figures["web"]
    # Five viewers' websockets for the 3 s run, each getting the poses (up to 60 a second); no browsers in --quick.
    assert web["viewers"] == 5 and len(web["sockets"]["per_viewer_per_s"]) == 5
    assert all(10 < messages < 200 for [messages] in web["sockets"]["per_viewer_per_s"])
    assert 100 < web["sockets"]["joint_state_per_s"] < 300 and 0.4 < web["sockets"]["sim_over_wall"] < 1.2
    assert 30 < web["sockets"]["web_view_rss_mb"]["end"] < 4000
    assert web["browsers"] == {"skipped": "not in a --quick run"}
    assert "5 viewers elsewhere" in result.stdout and "browsers on this machine" in result.stdout
    web_rows = 2

    if body == "mujoco":
        assert "memory_stages_mb" not in figures and machine["mujoco"].startswith("4.")
        assert len(figures["targets"]) == 8 + window_rows + recording_rows + leader_rows + web_rows
        return
    stages = figures["memory_stages_mb"]
    assert list(stages) == ["course", "plugins", "node"]
    for way in stages.values():
        assert list(way) == ["python", "imports (numpy, pyarrow, dora, pybullet)", "DIRECT client", "the arm loaded"]
        assert 5 < way["python"]["peak"] < way["DIRECT client"]["peak"] < way["the arm loaded"]["peak"] < 4000
    # Leaving out the renderer and the file cache keeps less after loading than the course's way.
    assert stages["plugins"]["the arm loaded"]["current"] < stages["course"]["the arm loaded"]["current"]
    assert "memory, peak | current RSS (MB)" in result.stdout

    assert len(figures["targets"]) == 8 + window_rows + recording_rows + leader_rows + web_rows
    assert all(isinstance(row["met"], bool) for row in figures["targets"])
    assert "targets:" in result.stdout and "joint_state per s" in result.stdout


LEADER_FIGURES = {"latency_ms": {"p50": 8.51, "p99": 17.26, "mean": 9.0, "max": 18.73, "count": 66, "moves": 67,
                                  "to_the_body_tick_ms": {"p50": 7.1, "p99": 16.02, "mean": 7.0, "max": 17.0, "count": 66},
                                  "body_tick_to_arrival_ms": {"p50": 0.9, "p99": 1.24, "mean": 0.9, "max": 1.3, "count": 66}},
                   "move_period_s": 0.3, "hand_step_deg": 4.0, "leader_tick_ms": 10.0}


@pytest.mark.parametrize("body", ["pybullet", "real"])
def test_the_tables_show_the_leader_rows_and_their_target_and_old_results_show_without(body):
    saved = json.loads(run_bench.DEFAULT_OUT[body].read_text())
    table = real_bench.table if body == "real" else run_bench.table
    saved.pop("leader", None)
    saved["targets"] = [row for row in saved["targets"] if not row["figure"].startswith("leader")]
    assert "leader" not in table(saved)  # a result from before the leader arm
    targets = real_bench.TARGETS if body == "real" else run_bench.TARGETS
    row = leader_bench.target(LEADER_FIGURES, targets["leader_latency_p99_ms"], body)
    assert row["met"] is (17.26 <= targets["leader_latency_p99_ms"])
    shown = table({**saved, "leader": LEADER_FIGURES, "targets": [*saved["targets"], row]})
    lines = shown.splitlines()
    latency_row = next(line for line in lines if line.startswith("leader moved -> joint_state (ms, p50 | p99 | max)"))
    assert latency_row.split()[-5:] == ["8.51", "|", "17.26", "|", "18.73"]
    assert any(line.startswith("  moves the body showed / moves made") and line.endswith("66 / 67") for line in lines)
    assert any("12-34 ms a teleoperation loop" in line for line in lines)
    target_line = next(line for line in lines if f"leader -> joint_state latency p99, {body} (ms)" in line)
    assert "17.260" in target_line and target_line.startswith("  met")


def test_the_leader_targets_are_25_ms_in_simulation_and_45_ms_to_the_emulated_follower():
    assert run_bench.TARGETS["leader_latency_p99_ms"] == 25.0 and real_bench.TARGETS["leader_latency_p99_ms"] == 45.0
    late = {**LEADER_FIGURES, "latency_ms": {**LEADER_FIGURES["latency_ms"], "p99": 30.0}}
    assert not leader_bench.target(late, 25.0, "pybullet")["met"] and leader_bench.target(late, 45.0, "real")["met"]


def test_show_prints_a_saved_result_and_refuses_what_is_not_one(tmp_path, capsys):
    latest = run_bench.ROOT / "bench" / "results" / "latest.json"
    assert run_bench.main(["--show", str(latest)]) == 0
    shown = capsys.readouterr().out
    assert shown.startswith("SO-101 simulation node benchmark (pybullet), ")
    assert f"{json.loads(latest.read_text())['dataflow']['joint_state_per_s']:.2f}" in shown

    not_json = tmp_path / "notes.txt"
    not_json.write_text("hello")
    assert run_bench.main(["--show", str(not_json)]) == 2
    assert capsys.readouterr().err.startswith(f"so101 bench: {not_json} is not a result of so101 bench (JSONDecodeError")
    assert run_bench.main(["--show", str(tmp_path / "missing.json")]) == 2
    assert capsys.readouterr().err == f"so101 bench: cannot read {tmp_path / 'missing.json'}: No such file or directory\n"


WEB_RUN = {"web_view_cpu_percent": 12.0, "web_view_rss_mb": {"start": 182.8, "end": 183.7}, "measured_s": 30.0,
           "ticks_missed": 0, "joint_state_per_s": 249.99, "sim_over_wall": 1.0}


def test_the_web_rows_judge_the_body_with_viewers_elsewhere_and_show_the_browsers_here():
    figures = {"viewers": 5, "sockets": {**WEB_RUN, "per_viewer_per_s": [[50.1]] * 4 + [[50.7]]},
               "browsers": {**WEB_RUN, "joint_state_per_s": 119.0, "sim_over_wall": 0.675,
                            "per_viewer_per_s": [[0.1, 0.2], [0.3, 0.3]] + [[0.2, 0.2]] * 3}}
    rows = web_bench.targets(figures, 247.5, 0.01)
    assert [row["met"] for row in rows] == [True, True]  # the browsers drawing on this machine are shown, not judged
    slow = {**figures, "sockets": {**figures["sockets"], "joint_state_per_s": 240.0, "sim_over_wall": 0.97}}
    assert [row["met"] for row in web_bench.targets(slow, 247.5, 0.01)] == [False, False]
    lines = [line.split() for line in web_bench.table_lines(figures)]
    assert "messages each viewer received per s (min | max) 50.1 | 50.7".split() in lines
    assert "each page: frames drawn per s (min | max) 0.2 | 0.3".split() in lines
    assert "joint_state per s | simulated / wall time 119.00 | 0.6750".split() in lines
    skipped = web_bench.table_lines({**figures, "browsers": {"skipped": "not in a --quick run"}})
    assert skipped[-1].endswith("not measured: not in a --quick run")


def test_show_prints_the_saved_web_result(capsys):
    latest = run_bench.DEFAULT_OUT["web"]
    assert run_bench.main(["--show", str(latest)]) == 0
    shown = capsys.readouterr().out
    assert shown.startswith("SO-101 web view benchmark (pybullet), ")
    assert f"{json.loads(latest.read_text())['web']['sockets']['joint_state_per_s']:.2f}" in shown


def saved_and_shown(name: str, capsys) -> tuple[dict, str]:
    """A saved result of bench/results/ and its table as `so101 bench --show` prints it."""
    saved = run_bench.ROOT / "bench" / "results" / name
    assert run_bench.main(["--show", str(saved)]) == 0
    return json.loads(saved.read_text()), capsys.readouterr().out


@pytest.mark.parametrize("name", ["latest-cameras.json", "latest-cameras-mujoco.json"])
def test_the_saved_camera_results_show_each_cameras_rates_and_the_targets(name, capsys):
    result, shown = saved_and_shown(name, capsys)
    assert shown.startswith(f"SO-101 task cameras benchmark ({result['body']}), ")
    for camera, key in (("front", "observation.images.front"), ("wrist", "observation.images.wrist")):
        alone = result["cameras"]["alone"][key]
        beside = result["cameras"]["beside_physics"]["new_pictures_per_s"][key]
        assert f"{alone['pictures_per_s']:.1f} | {beside:.1f}" in shown, camera
        share = result["cameras"]["beside_physics"]["new_while_moving"][key]
        assert re.search(rf"new pictures while the arm moves \(share of frames\) +{share:.0%}$", shown, re.M), camera
        assert f"{camera} camera: new pictures while the arm moves" in shown
    assert re.search(rf"^pictures drawn by +{re.escape(result['cameras']['alone']['drawn_by'])}$", shown, re.M)
    assert f"{result['cameras']['beside_physics']['joint_state_per_s']:.2f}" in shown
    # Each renderer option with its time and its picture's difference from the camera's own, the first's being 0.
    renderers = result["cameras"]["renderers"]
    assert list(renderers) == list(camera_bench.RENDERERS[result["body"]])
    for option, figures in renderers.items():
        if "skipped" in figures:  # an option this machine lacks (OSMesa) is named, with why
            assert re.search(rf"^  {re.escape(option)} +not measured: {re.escape(figures['skipped'])}$", shown, re.M)
            continue
        assert re.search(rf"^  {re.escape(option)} +{figures['ms']['p50']:.1f} \| {figures['ms']['p99']:.1f} +"
                         rf"{figures['differs_from_camera']:.1f}$", shown, re.M), option
    assert renderers[list(renderers)[0]]["differs_from_camera"] == 0
    # Where the CPU went while recording: each process of the dataflow, in cores.
    cores = result["cameras"]["beside_physics"]["cpu_cores"]
    assert {"camera", "recorder", "dora run"} <= set(cores)
    assert 0 < cores["camera"] and sum(cores.values()) <= 1.02 * result["machine"]["cores"]
    assert re.search(rf"^    camera +{cores['camera']:.2f}$", shown, re.M)


def test_cameras_refuse_the_real_arm_in_one_line(capsys):
    assert run_bench.main(["--cameras", "--body", "real"]) == 1
    assert capsys.readouterr().err == "so101 bench: --cameras measures a simulation's pictures: --body pybullet or mujoco\n"


@pytest.mark.parametrize("name", ["latest-demos.json", "latest-demos-mujoco.json"])
def test_the_saved_demos_results_show_each_run_and_where_a_frames_time_goes(name, capsys):
    result, shown = saved_and_shown(name, capsys)
    assert shown.startswith(f"SO-101 demonstrations benchmark ({result['body']}), ")
    runs = result["demos"]["runs"]
    assert list(runs) == ["no_video_1_workers", "no_video_2_workers", "video_1_workers", "video_2_workers"]
    for run in runs.values():
        label = ("no video" if run["image_size"] is None else "two cameras 320x240") + (
            ", 1 worker" if run["workers"] == 1 else ", 2 workers")
        assert re.search(rf"^{label} +{run['episodes_per_min']:.1f} \| {run['times_real_time']:.1f} +\(", shown, re.M)
        assert run["episodes_per_min"] == pytest.approx(60 * run["episodes"] / run["wall_s"], rel=0.01)
    stages = result["demos"]["ms_per_frame"]
    assert all(stages[stage] > 0 for stage in ("physics", "expert", "pictures", "encoding"))
    assert f"{stages['pictures']:.2f}" in shown
    assert "demos without video, 1 worker: × real time" in shown


def test_a_frames_stages_are_timed_in_process_on_the_expert_s_episode(tmp_path):
    from bench import demos_bench

    stages = demos_bench.stage_times(tmp_path, "mujoco", (64, 48), 10)
    assert set(stages) == {"physics", "expert", "pictures", "encoding"}
    assert all(0 < milliseconds < 1000 for milliseconds in stages.values()), stages
    assert list(tmp_path.iterdir()) == []  # its videos are gone


def test_demos_refuse_the_real_arm_in_one_line(capsys):
    assert run_bench.main(["--demos", "--body", "real"]) == 1
    assert capsys.readouterr().err == "so101 bench: --demos measures a simulation's episodes: --body pybullet or mujoco\n"


@pytest.mark.dataflow
def test_dora_alone_times_the_lockstep_loops_messages_between_empty_nodes(tmp_path):
    from bench.demos_bench import dora_alone_ms

    ms = dora_alone_ms(tmp_path, 50)
    assert 0 < ms < 1000 and (tmp_path / "echo_ms.txt").read_text().strip() == f"{ms:.3f}"


@pytest.mark.parametrize("name", ["latest-gym.json", "latest-gym-mujoco.json"])
def test_the_saved_gym_results_show_each_run_beside_the_dataflows_lockstep(name, capsys):
    result, shown = saved_and_shown(name, capsys)
    runs, title = result["gym"]["runs"], f"SO-101 Gymnasium environment benchmark ({result['body']}), "
    assert shown.startswith(title) and list(runs) == ["state_1_env", "state_2_envs", "all_2_envs", "all_1_env"]
    rows = {(run["obs_type"], run["environments"]): run for run in runs.values()}
    for (obs_type, environments), label in {("state", 1): r"no pictures \(state\), one environment",
                                            ("state", 2): r"no pictures \(state\), async vector of 2",
                                            ("all", 2): r"both cameras 320x240 \(all\), async vector of 2",
                                            ("all", 1): r"both cameras 320x240 \(all\), one environment"}.items():
        run = rows[obs_type, environments]
        assert re.search(rf"^{label} +{run['steps_per_s']:.0f} \| {run['times_real_time']:.1f}", shown, re.M), label
        assert run["times_real_time"] == pytest.approx(run["steps_per_s"] / 25, abs=0.1)
    assert f"{result['gym']['dataflow_frames_per_s']:.0f}" in shown
    assert "gym steps/s without pictures, one env / dataflow lockstep frames/s" in shown


def test_the_gym_bench_counts_a_vectors_steps_for_each_of_its_environments():
    from bench import gym_bench

    run = gym_bench.steps_per_s("pybullet", "state", 2, 0.3, (64, 48), warmup_s=0.1)
    assert run["environments"] == 2 and run["steps_per_s"] > 100 and run["seconds"] >= 0.3
    assert gym_bench.sweep_action(0, 2).shape == (2, 6)


def test_gym_refuses_the_real_arm_in_one_line(capsys):
    assert run_bench.main(["--gym", "--body", "real"]) == 1
    assert capsys.readouterr().err == "so101 bench: --gym measures a simulation's environment: --body pybullet or mujoco\n"


def test_every_saved_result_is_newer_than_the_code_it_measures():
    """The change that moves a figure reruns it: no commit after a result was saved changed the code it measures
    (`so101 bench --stale` names them, with the command that reruns each)."""
    from bench import staleness

    if not staleness.has_history(run_bench.ROOT):
        pytest.skip("this checkout has no git history (or a shallow one): a result's age cannot be told")
    policy_round_trips = {"latest-round-trip.json", "latest-round-trip-sealed.json"}  # a trained policy's: by hand
    assert {measured.result for measured in staleness.MEASURED} == \
        {path.name for path in run_bench.DEFAULT_OUT.values()} - policy_round_trips
    assert staleness.stale_lines(run_bench.ROOT) == []


def test_a_result_is_stale_once_a_later_commit_changes_its_code_until_it_is_saved_again(tmp_path):
    from bench import staleness

    def commit(path: str, text: str) -> None:
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path).write_text(text)
        staleness.git(tmp_path, "add", path)
        staleness.git(tmp_path, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", f"{path} {text}")

    staleness.git(tmp_path, "init", "-q")
    measured = staleness.Measured("latest-x.json", ("so101/x.py", "nodes/"), "so101 bench --x")
    commit("so101/x.py", "1")
    commit("bench/results/latest-x.json", "{}")
    assert staleness.changes_since_saved(tmp_path, measured) == []
    commit("so101/other.py", "1")  # not what it measures
    commit("nodes/x_node.py", "2")  # in a folder it measures
    assert [line.split(" ", 1)[1] for line in staleness.changes_since_saved(tmp_path, measured)] == ["nodes/x_node.py 2"]
    commit("bench/results/latest-x.json", '{"again": 1}')
    assert staleness.changes_since_saved(tmp_path, measured) == []
