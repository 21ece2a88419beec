"""`so101 bench --round-trip`: a policy's frame -> action round trip in lockstep, with the policy on the body's
daemon and on another daemon of a cluster, back to back.

The same `so101 eval` run twice (so101.launch.lockstep: the body, nodes/policy.py, the episodes' runner),
the body and the runner on one daemon, the policy first on that daemon, then on the other: every frame then
crosses to the policy's daemon and its joint_cmd comes back over Zenoh. The figure is the round trip as the
body sees it: from the moment it begins to send a frame (its physics steps done) to the moment the
joint_cmd that answers that frame arrives (the body's lockstep tick log, SO101_TICK_LOG), over every
frame of the runner's episodes but the first (torch's first call may be there). It holds the body's
sends, the policy's own time (a new action chunk's inference, or a step along the chunk, with LeRobot's
pre- and post-processing) and the messages both ways; and where dora lost one of them, the runner's
wait (nodes/episodes.py: SILENCE_S) until it asks the body for the frame again (counted apart: the
frames answered after a second or more). Beside it, the run's wall time. Both runs record their
episodes (every frame, failed or not), which must be the same, frame for frame: a policy elsewhere
scores as one beside the body.

Without --coordinator, a coordinator and two daemons `arm` and `desk` on 127.0.0.1 (loopback: dora's and
Zenoh's own costs, no network's); with --coordinator ADDR --machine HERE --policy-machine NAME, a cluster
someone runs (a sealed one included), the body on HERE (this machine), the policy on HERE then on NAME.
With --sealed, the sealed rig: machines `arm` and `desk` of network namespaces here, WireGuard only between
them (so101.runtime.cluster.sealed_rig, as root), and this bench run again on `arm` against its coordinator.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from bench.common import machine_facts, machine_line, tick_records
from so101.bodies.looks import DEFAULT_LOOKS
from so101.bodies.physics import DEFAULT_PHYSICS
from so101.launch.lockstep import Driver, flows_for, run_flows
from so101.launch.on_cluster import ClusterPlace
from so101.runtime.dataflow import POLICY_NODE_FILE, ROOT
from so101.stats import summary
from so101.tasks import task_named

TASK = "cube_to_box"
DEFAULT_POLICY = ROOT / "tests" / "data" / "policy_act_tiny"  # a tiny ACT: its README.md says how it was made
LOOPBACK_HERE, LOOPBACK_ELSEWHERE = "arm", "desk"
DATA_FILE = Path("data") / "chunk-000" / "file-000.parquet"
LOST_MS = 1000.0  # a frame answered this late waited for the runner's `again` after a lost message


class RoundTripError(RuntimeError):
    """The run could not be made or did not finish; str() is one line."""


def policy_driver(policy: Path, python: Path | None, elsewhere: bool) -> tuple[Driver, tuple[int, int] | None]:
    from so101.policy.choice import choose_policy

    try:
        chosen = choose_policy(policy, python, TASK, task_named(TASK).object_state_names, python_elsewhere=elsewhere)
    except ValueError as error:
        raise RoundTripError(str(error)) from None
    return (Driver("policy", POLICY_NODE_FILE, chosen.inputs, chosen.env(TASK, "cpu"), python=str(chosen.python)),
            chosen.picture_size)


def one_run(work: Path, driver: Driver, picture_size: tuple[int, int] | None, episodes: int, seed: int,
            time_limit_s: float, place: ClusterPlace) -> dict:
    """The episodes with the policy on place.policy_machine: the round trips (ms) and the outcomes."""
    args = argparse.Namespace(task=TASK, episodes=episodes, seed=seed, workers=1, time_limit=time_limit_s,
                              looks=DEFAULT_LOOKS, physics=DEFAULT_PHYSICS, body="pybullet", lang="en")
    pictures = ("image", "wrist_image") if picture_size else ()
    (flow,) = flows_for(args, work, driver, pictures, picture_size,
                        lambda folder: {"SO101_RECORD_DIR": str(folder / "dataset"), "SO101_KEEP": "all"})
    tick_log = work / "frames.bin"
    flow = replace(flow, body_env={"SO101_TICK_LOG": str(tick_log)})
    started_s = time.monotonic()
    # A name of its own (bench-same_daemon-PID-0, ...): the run before may still be stopping under its own.
    outcomes, problem = run_flows(f"bench-{work.name}", [flow], work, None,
                                  lambda outcome, worker: print(outcome.line(), flush=True), place)
    wall_s = time.monotonic() - started_s
    if problem:
        raise RoundTripError(problem)
    if not tick_log.exists():
        raise RoundTripError(f"the body wrote no tick log ({tick_log}): is --machine this machine's daemon?")
    # Each answered frame's (out, answer in, episode); episode 0 is the body's start, answered or not before the
    # runner's first reset comes. Of the runner's, the first is left out too: torch's first call may be there.
    frames = [(sent, answered) for sent, answered, episode in tick_records(tick_log.read_bytes()) if episode > 0]
    round_trips_ms = [(answered - sent) / 1e6 for sent, answered in frames[1:]]
    return {"round_trip_ms": round_trips_ms, "wall_s": wall_s, "outcomes": outcomes,
            "data": (work / "dataset" / DATA_FILE).read_bytes()}


def run_round_trip_benchmark(policy: Path, python: Path | None, episodes: int, seed: int, time_limit_s: float | None,
                             place: ClusterPlace | None) -> dict:
    """The two runs, back to back, on the cluster at `place` (None: a loopback one of this run's own); each
    episode `time_limit_s` long at most (None: so101 eval's)."""
    from so101.runtime.cluster import Cluster, ClusterError
    from so101.tasks.episodes import DEFAULT_TIME_LIMIT_S

    time_limit_s = time_limit_s or DEFAULT_TIME_LIMIT_S
    load_start = os.getloadavg()
    driver, picture_size = policy_driver(policy, python, elsewhere=place is not None)
    with tempfile.TemporaryDirectory(prefix="so101-bench-round-trip-") as tmp:
        work = Path(tmp)
        cluster = None
        token = os.environ.get("DORA_AUTH_TOKEN")
        try:
            if place is None:  # the runs join it as a cluster someone runs, with its token
                cluster = Cluster(work / "cluster")
                cluster.start_coordinator()
                cluster.start_daemon(LOOPBACK_HERE)
                cluster.start_daemon(LOOPBACK_ELSEWHERE)
                os.environ["DORA_AUTH_TOKEN"] = cluster.token or ""
                place = ClusterPlace("127.0.0.1", cluster.coordinator_port, LOOPBACK_HERE, ROOT, LOOPBACK_ELSEWHERE)
            elsewhere = place.policy_machine
            assert elsewhere is not None
            runs = {}
            for key, machine in (("same_daemon", place.here), ("other_daemon", elsewhere)):
                print(f"the body on {place.here!r}, the policy on {machine!r}: {episodes} episodes from seed {seed} ...",
                      flush=True)
                runs[key] = one_run(work / key, driver, picture_size, episodes, seed, time_limit_s,
                                    replace(place, policy_machine=machine))
        except ClusterError as error:
            raise RoundTripError(str(error)) from None
        finally:
            if cluster is not None:
                cluster.stop()
                if token is None:
                    os.environ.pop("DORA_AUTH_TOKEN", None)
                else:
                    os.environ["DORA_AUTH_TOKEN"] = token

    def keep(run: dict) -> dict:
        outcomes = run["outcomes"]
        inference = [ms for outcome in outcomes for ms in outcome.inference_ms]
        return {"round_trip_ms": {key: summary(run["round_trip_ms"])[key] for key in ("p50", "p99", "mean", "max", "count")},
                "lost": sum(ms >= LOST_MS for ms in run["round_trip_ms"]), "wall_s": run["wall_s"],
                "inference_ms": summary(inference) if inference else None,
                "successes": sum(outcome.success for outcome in outcomes), "episodes": len(outcomes),
                "frames": sum(outcome.frames for outcome in outcomes)}

    same, other = runs["same_daemon"], runs["other_daemon"]
    return {
        "body": "round-trip",
        "machine": machine_facts(),
        "load_average_1_5_15min": {"start": list(load_start), "end": list(os.getloadavg())},
        "settings": {"policy": str(policy), "episodes": episodes, "seed": seed, "time_limit_s": time_limit_s,
                     "cluster": "loopback" if cluster is not None else f"{place.coordinator_addr}:{place.coordinator_port}",
                     "here": place.here, "policy_machine": elsewhere},
        "same_daemon": keep(same),
        "other_daemon": keep(other),
        # The same episodes, frame for frame: the outcomes, and every recorded state and action.
        "same_episodes": (same["data"] == other["data"]
                          and [replace(outcome, inference_ms=[]) for outcome in same["outcomes"]]
                          == [replace(outcome, inference_ms=[]) for outcome in other["outcomes"]]),
    }


def run_sealed_round_trip(options: list[str]) -> dict:
    """The two runs across the sealed rig: the body on machine `arm`, the policy on `arm` then on `desk`,
    every message between the two through WireGuard. `options`: the run's own (--policy, --episodes, ...)."""
    from so101.runtime.cluster import Cluster, ClusterError, sealed_rig
    from so101.runtime.netns import rig_problem
    from so101.runtime.wireguard import SealError, missing_tools

    problem = rig_problem() or missing_tools()
    if problem:
        raise RoundTripError(f"--sealed: {problem}")
    with tempfile.TemporaryDirectory(prefix="so101-bench-sealed-") as tmp:
        work = Path(tmp)
        rig = cluster = None
        try:
            rig, seal = sealed_rig(work, [LOOPBACK_HERE, LOOPBACK_ELSEWHERE])
            cluster = Cluster(work / "cluster", seal=seal)
            cluster.start_coordinator()
            for machine in (LOOPBACK_HERE, LOOPBACK_ELSEWHERE):
                cluster.start_daemon(machine)
            result_file = work / "result.json"
            run = subprocess.Popen(
                [*rig.on(LOOPBACK_HERE), sys.executable, "-m", "so101.cli", "bench", "--round-trip", *options,
                 "--coordinator", cluster.coordinator_addr, "--machine", LOOPBACK_HERE,
                 "--policy-machine", LOOPBACK_ELSEWHERE, "--out", str(result_file)],
                env=dict(os.environ, DORA_AUTH_TOKEN=cluster.token or ""), stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT, text=True)
            assert run.stdout is not None
            for line in run.stdout:  # its progress, up to its table (printed here, said to be sealed)
                if not line.strip():
                    break
                print(line, end="", flush=True)
            said = run.stdout.read()
            if run.wait() != 0:
                raise RoundTripError(f"the run on machine {LOOPBACK_HERE!r} failed: {said.strip()[-300:]}")
            result = json.loads(result_file.read_text(encoding="utf-8"))
        except (ClusterError, SealError) as error:
            raise RoundTripError(str(error)) from None
        except subprocess.CalledProcessError as error:  # the rig: `ip` or wg-quick refused
            raise RoundTripError(f"{' '.join(map(str, error.cmd))} failed: {(error.stderr or '').strip()[-300:]}") from None
        finally:
            if cluster is not None:
                cluster.stop()
            if rig is not None:
                rig.tear_down()
    result["settings"]["sealed"] = True
    return result


def table(result: dict) -> str:
    settings, one, two = result["settings"], result["same_daemon"], result["other_daemon"]
    where = ("on 127.0.0.1 (loopback, not a network)" if settings["cluster"] == "loopback"
             else f"across WireGuard between two network namespaces of one computer (the coordinator at "
                  f"{settings['cluster']})" if settings.get("sealed")
             else f"on the cluster of the coordinator at {settings['cluster']}")

    def ms(figures: dict | None, keys: tuple[str, ...] = ("p50", "p99")) -> str:
        return " | ".join(f"{figures[key]:.2f}" for key in keys) if figures else "none"

    here, there = f"policy on {settings['here']}", f"policy on {settings['policy_machine']}"
    rows = [
        ("frames answered", one["round_trip_ms"]["count"], two["round_trip_ms"]["count"]),
        ("frame -> joint_cmd at the body (ms, p50 | p99)", ms(one["round_trip_ms"]), ms(two["round_trip_ms"])),
        ("frames answered after a lost message (>= 1 s)", one["lost"], two["lost"]),
        ("the longest frame -> joint_cmd (ms)", f"{one['round_trip_ms']['max']:.0f}", f"{two['round_trip_ms']['max']:.0f}"),
        ("new action chunk's inference (ms, p50 | p99)", ms(one["inference_ms"]), ms(two["inference_ms"])),
        ("episodes in the box", f"{one['successes']}/{one['episodes']}", f"{two['successes']}/{two['episodes']}"),
        ("the run's wall time, start-up included (s)", f"{one['wall_s']:.1f}", f"{two['wall_s']:.1f}"),
    ]
    return "\n".join([
        f"SO-101 policy round trip in lockstep, the body on {settings['here']}, {where}, {result['machine']['date']}",
        machine_line(result),
        f"policy {settings['policy']}, {settings['episodes']} episodes from seed {settings['seed']}, "
        f"time limit {settings['time_limit_s']:g} s",
        "",
        f"{'figure':<48} {here:>16} {there:>16}",
        *(f"{name:<48} {str(first):>16} {str(second):>16}" for name, first, second in rows),
        f"the same episodes, frame for frame (every state and action): {'yes' if result['same_episodes'] else 'NO'}",
    ])
