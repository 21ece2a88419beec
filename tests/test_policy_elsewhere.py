"""The policy on another machine of a dora cluster (`--policy-machine`): so101 eval, so101 teleop and so101 bench
--round-trip, on a coordinator with a token and daemons `arm` (the body's, "this machine") and `desk` (the
policy's) on 127.0.0.1, as so101/runtime/cluster.py starts them; docs/loop/policy-elsewhere.md."""

from __future__ import annotations

import json
import os
import re
import subprocess
import threading
import time
from pathlib import PurePath

import pytest

from so101.bodies.registry import BODIES
from so101.launch.lockstep import Driver, Flow, Placement, lockstep_dataflow
from so101.launch.on_cluster import placed
from so101.runtime.cluster import Cluster
from so101.runtime.dataflow import POLICY_NODE_FILE
from tests.helpers.dataflow import ROOT, SO101, dora_env, error_lines
from tests.test_policy import TINY_POLICY

HERE, ELSEWHERE = "arm", "desk"


@pytest.fixture
def cluster(tmp_path):
    with Cluster(tmp_path / "cluster") as started:
        started.start_coordinator()
        started.start_daemon(HERE)
        started.start_daemon(ELSEWHERE)
        yield started


def on(cluster: Cluster, **env: str) -> dict[str, str]:
    """The environment of a command run against `cluster`: its token, as a user exports it."""
    return dora_env(DORA_AUTH_TOKEN=cluster.token or "", **env)


def ran_on(cluster: Cluster, *node_ids: str) -> dict[str, set[str]]:
    """Which daemon ran which node: each keeps its nodes' logs in its own folder."""
    return {machine: {node for node in node_ids if cluster.node_log(machine, node)} for machine in (HERE, ELSEWHERE)}


# -- where the nodes go -----------------------------------------------------------------------------------------

def test_the_lockstep_dataflow_puts_the_policy_on_its_machine_under_that_machines_folder():
    driver = Driver("policy", POLICY_NODE_FILE, ("joint_state",), {}, python="/opt/policy-env/bin/python")
    flow = Flow(BODIES["pybullet"], driver, {"SO101_TASK": "cube_to_box", "SO101_SEED": "0", "SO101_TIME_LIMIT_S": "2"}, "en")
    nodes = {node["id"]: node for node in
             lockstep_dataflow(flow, Placement(HERE, HERE, ELSEWHERE), PurePath("/home/lab/so101"))["nodes"]}
    assert {node_id: node["deploy"] for node_id, node in nodes.items()} == {
        "simulation": {"machine": HERE}, "policy": {"machine": ELSEWHERE}, "episodes": {"machine": HERE}}
    # The policy's Python and node file are paths on its machine; the body and the runner run here.
    assert (nodes["policy"]["path"], nodes["policy"]["args"]) == ("/opt/policy-env/bin/python",
                                                                 "/home/lab/so101/nodes/policy.py")
    assert nodes["simulation"]["path"] == str(ROOT / "nodes" / "simulation_node.py")
    assert nodes["episodes"]["path"] == str(ROOT / "nodes" / "episodes.py")


def test_placed_puts_every_node_here_but_those_named_elsewhere():
    descriptor = {"nodes": [{"id": "simulation", "path": "a.py"}, {"id": "keyboard_control", "path": "dynamic"},
                            {"id": "policy", "path": "/py", "args": "b.py"}]}
    assert [node["deploy"]["machine"] for node in placed(descriptor, HERE, {"policy": ELSEWHERE})["nodes"]] == [
        HERE, HERE, ELSEWHERE]


@pytest.mark.parametrize("args, message", [
    (["eval", "--expert", "--task", "cube_to_box", "--policy-machine", "desk"],
     "so101 eval: --policy-machine desk places the policy: it goes with --policy DIR"),
    (["eval", "--policy", str(TINY_POLICY), "--task", "cube_to_box", "--policy-machine", "desk"],
     "so101 eval: --policy-machine desk goes with --coordinator ADDR[:PORT] and --machine ID: the cluster whose "
     "daemon runs the policy"),
    (["eval", "--policy", str(TINY_POLICY), "--task", "cube_to_box", "--policy-machine", "desk", "--coordinator",
      "10.0.0.1", "--machine", "arm", "--policy-python", "bin/python"],
     "so101 eval: --policy-python bin/python must be an absolute path on the policy's machine"),
    (["teleop", "--policy-machine", "desk"], "so101 teleop: --policy-machine desk places the policy: it goes with "
                                             "--policy DIR"),
    (["teleop", "--task", "cube_to_box", "--policy", str(TINY_POLICY), "--policy-machine", "desk"],
     "so101 teleop: --policy-machine desk goes with --coordinator ADDR[:PORT] and --machine ID: the cluster whose "
     "daemon runs the policy"),
    (["teleop", "--coordinator", "10.0.0.1"], "so101 teleop: --coordinator needs --machine ID: the machine id of "
                                              "this machine's daemon, where the body and the prompt run"),
    (["bench", "--policy-machine", "desk"], "so101 bench: --policy-machine: --round-trip's options; they go with "
                                            "--round-trip"),
    (["bench", "--round-trip", "--coordinator", "10.0.0.1", "--machine", "arm"],
     "so101 bench: --round-trip on a cluster needs --policy-machine NAME: the daemon to run the policy on, against "
     "--machine's"),
])
def test_a_policy_machine_without_what_it_needs_is_one_line(args, message):
    done = subprocess.run([str(SO101), *args, "--lang", "en"] if args[0] != "bench" else [str(SO101), *args],
                          capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL, env=dora_env())
    assert done.returncode != 0
    assert error_lines(done.stderr) == [message], done.stderr


# -- so101 eval ---------------------------------------------------------------------------------------------------

@pytest.mark.dataflow
def test_eval_with_the_policy_on_another_daemon_scores_as_on_one_machine(cluster, policy_python):
    coordinator = f"127.0.0.1:{cluster.coordinator_port}"
    done = subprocess.run(
        [str(SO101), "eval", "--task", "cube_to_box", "--policy", str(TINY_POLICY), "--policy-python", str(policy_python),
         "--episodes", "2", "--seed", "5", "--time-limit", "2", "--workers", "2", "--lang", "en",
         "--coordinator", coordinator, "--machine", HERE, "--policy-machine", ELSEWHERE],
        capture_output=True, text=True, timeout=300, env=on(cluster))
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.strip().splitlines()
    assert lines[1].startswith("so101 eval: note: the policy's joints are taken as degrees")  # its dataset is elsewhere
    assert lines[4:6] == ["eval: worker 0 (seeds 5..5) on machine 'arm', its policy on machine 'desk'",
                          "eval: worker 1 (seeds 6..6) on machine 'arm', its policy on machine 'desk'"]
    # What test_policy.py's test_eval_scores_a_policy_in_lockstep_episode_by_episode scores on one machine.
    assert lines[6:9] == ["episode 0 (seed 5): failed (time limit, 2.0 s), 51 frames",
                          "episode 1 (seed 6): failed (time limit, 2.0 s), 51 frames",
                          "success: 0/2 (0%, 95% CI 0–66%, Wilson), mean time to success none (no success)"]
    assert ran_on(cluster, "simulation", "episodes", "policy") == {HERE: {"simulation", "episodes"},
                                                                   ELSEWHERE: {"policy"}}
    refused = subprocess.run(
        [str(SO101), "eval", "--task", "cube_to_box", "--policy", str(TINY_POLICY), "--lang", "en",
         "--coordinator", coordinator, "--machine", HERE, "--policy-machine", "laptop"],
        capture_output=True, text=True, timeout=60, env=on(cluster))
    assert refused.returncode == 1
    assert refused.stderr.strip().splitlines()[-1] == (
        f"so101 eval: no daemon with machine id 'laptop' on the coordinator at {coordinator}, for --policy-machine "
        f"(its daemons: arm, desk; is DORA_AUTH_TOKEN its token?)")
    # A Python the policy's machine does not have: dora's line, and what to check there. A Python without
    # LeRobot: the node's own refusal, from its log on `desk`, as the coordinator streams it.
    refusals = {}
    for python in ("/no/python", str(ROOT / ".venv" / "bin" / "python")):
        refused = subprocess.run(
            [str(SO101), "eval", "--task", "cube_to_box", "--policy", str(TINY_POLICY), "--policy-python", python,
             "--lang", "en", "--coordinator", coordinator, "--machine", HERE, "--policy-machine", ELSEWHERE],
            capture_output=True, text=True, timeout=60, env=on(cluster))
        assert refused.returncode == 1
        refusals[python] = refused.stderr.strip().splitlines()[-1]
    assert refusals["/no/python"] == (
        "so101 eval: dora start failed: dataflow failed to start hint: if nodes require building, run `dora build "
        "<dataflow.yml>` first Caused by: failed to prepare node policy (on machine 'desk': is /no/python there, and "
        f"the project at {ROOT}?)")
    assert refusals[str(ROOT / ".venv" / "bin" / "python")] == (
        f"so101 eval: [policy] cannot start: LeRobot does not import in {ROOT}/.venv/bin/python (ModuleNotFoundError: "
        "No module named 'torch'): run the node with a policy environment's Python (so101 policy-env)")


# -- so101 teleop -------------------------------------------------------------------------------------------------

class Typed:
    """A command in a subprocess, typed at through a pipe; its output lines as they come."""

    def __init__(self, args: list[str], env: dict[str, str]):
        self.process = subprocess.Popen(args, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        stderr=subprocess.STDOUT, text=True, env=env)
        self.lines: list[str] = []
        self._reader = threading.Thread(target=lambda: self.lines.extend(line.rstrip("\n") for line in self.process.stdout))
        self._reader.start()

    def wait_for(self, pattern: str, timeout_s: float) -> re.Match:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for line in list(self.lines):
                if found := re.fullmatch(pattern, line):
                    return found
            if self.process.poll() is not None and not self._reader.is_alive():
                break
            time.sleep(0.1)
        raise AssertionError(f"no line {pattern!r} within {timeout_s} s:\n" + "\n".join(self.lines))

    def type(self, line: str) -> None:
        self.process.stdin.write(line + "\n")
        self.process.stdin.flush()

    def end(self, timeout_s: float) -> int:
        self.process.stdin.close()
        code = self.process.wait(timeout_s)
        self._reader.join(5)
        return code


@pytest.mark.dataflow
def test_teleop_drives_with_the_policy_on_another_daemon_and_quit_leaves_nothing_running(tmp_path, cluster,
                                                                                          policy_python):
    teleop = Typed([str(SO101), "teleop", "--mode", "direct", "--lang", "en", "--task", "cube_to_box", "--seed", "3",
                    "--policy", str(TINY_POLICY), "--policy-python", str(policy_python), "--log", str(tmp_path / "dora.log"),
                    "--coordinator", f"127.0.0.1:{cluster.coordinator_port}", "--machine", HERE,
                    "--policy-machine", ELSEWHERE],
                   on(cluster, SO101_DAEMON_PORT=str(cluster.daemon_ports[HERE]),  # the prompt joins through `arm`
                      SO101_POSES_FILE=str(tmp_path / "poses.json"), SO101_HISTORY_FILE=str(tmp_path / "history")))
    try:
        teleop.wait_for(r"starting the dataflow on the cluster of the coordinator at 127\.0\.0\.1:\d+ \(dora start, "
                        r"direct mode\): the body and the prompt on machine 'arm', the policy on machine 'desk', "
                        r"log in .*", 10)
        teleop.wait_for(r"simulation ready, starting the keyboard prompt", 120)
        angles = r"  joint angles now: \[(-?[\d.]+), (-?[\d.]+), (-?[\d.]+), (-?[\d.]+), (-?[\d.]+)\].*"
        teleop.type("policy on")
        teleop.wait_for(re.escape("  [policy] act is driving: any move you type takes over; policy off stops it"), 20)
        time.sleep(3.0)
        teleop.type("state")
        driven = [float(angle) for angle in teleop.wait_for(angles, 10).groups()]
        teleop.type("quit")
        assert teleop.end(60) == 0, "\n".join(teleop.lines)
    finally:
        if teleop.process.poll() is None:
            teleop.process.kill()
    assert max(abs(angle) for angle in driven) > 2.0, driven  # the policy on `desk` moved the arm on `arm`
    assert teleop.lines[-2:] == ["stopping the dataflow...", "dataflow stopped"]
    assert ran_on(cluster, "simulation", "expert", "policy") == {HERE: {"simulation", "expert"}, ELSEWHERE: {"policy"}}
    # Quit stopped the dataflow on both machines: the cluster runs its coordinator and daemons, nothing else.
    listed = [json.loads(line) for line in cluster.cli("list", "--format", "json").stdout.splitlines()
              if line.startswith("{")]
    assert not [entry for entry in listed if str(entry.get("status", "")).lower() == "running"], listed
    assert sorted(cluster.leftover_processes()) == sorted(process.pid for process in cluster.processes.values())
    # A Python the policy's machine does not have: dora's line, not its backtrace, and what to check there.
    missing = subprocess.run(
        [str(SO101), "teleop", "--mode", "direct", "--lang", "en", "--task", "cube_to_box", "--policy", str(TINY_POLICY),
         "--policy-python", "/no/python", "--log", str(tmp_path / "missing.log"), "--coordinator",
         f"127.0.0.1:{cluster.coordinator_port}", "--machine", HERE, "--policy-machine", ELSEWHERE],
        input="quit\n", capture_output=True, text=True, timeout=120,
        env=on(cluster, SO101_DAEMON_PORT=str(cluster.daemon_ports[HERE])))
    assert missing.returncode == 1
    assert missing.stderr.strip() == ("so101 teleop: dora could not start the dataflow on machine 'desk': failed to "
                                      f"prepare node policy (is /no/python there, and {ROOT}/nodes/policy.py?)")


# -- so101 bench --round-trip -------------------------------------------------------------------------------------

@pytest.mark.dataflow
def test_the_round_trip_bench_runs_the_same_episodes_with_the_policy_on_either_daemon(policy_python):
    from bench import round_trip_bench

    token = os.environ.get("DORA_AUTH_TOKEN")
    result = round_trip_bench.run_round_trip_benchmark(TINY_POLICY, policy_python, 1, 7, 2.0, None)
    assert os.environ.get("DORA_AUTH_TOKEN") == token  # the loopback cluster's token was this process's for the runs only
    one, two = result["same_daemon"], result["other_daemon"]
    assert result["settings"]["cluster"] == "loopback"
    assert (result["settings"]["here"], result["settings"]["policy_machine"]) == (HERE, ELSEWHERE)
    # 51 frames; the body takes the answers to the first 50 (the 51st is the time limit's: it holds still), and
    # the figures leave the first out (torch's first call), and the body's start before the runner's reset.
    assert one["frames"] == two["frames"] == 51
    assert one["round_trip_ms"]["count"] == two["round_trip_ms"]["count"] == 49
    assert result["same_episodes"] is True
    assert 0 < one["round_trip_ms"]["p50"] <= one["round_trip_ms"]["p99"] <= one["round_trip_ms"]["max"]
    assert one["inference_ms"]["count"] == two["inference_ms"]["count"] == 6  # chunks of 10: frames 0, 10, ... 50
    shown = round_trip_bench.table(result)
    assert "policy on arm   policy on desk" in shown
    assert shown.endswith("the same episodes, frame for frame (every state and action): yes")
