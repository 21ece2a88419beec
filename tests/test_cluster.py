"""The dataflow on a dora cluster: a coordinator with token authentication and two daemons on
127.0.0.1 under different machine ids (so101/cluster.py, as `so101 cluster-demo` runs it)."""

from __future__ import annotations

import json
import re
import os
import subprocess
import time

import pytest

from so101.cluster import BODY_MACHINE, CLUSTER_DATAFLOW, PROMPT_MACHINE, Cluster, ClusterError
from so101.dataflow import LOADED_MARKS, dataflow_copy, write_dataflow
from tests.dataflow_helpers import PROMPT_COMMAND, RECORDER, prompt_env
from tests.test_dataflow import check_the_record, type_the_script

pytestmark = pytest.mark.dataflow


def start_with_recorder(cluster: Cluster, tmp_path, record_file, recorder_machine: str) -> None:
    """The coordinator, daemons `arm` and `desk`, and dataflow_cluster.yml with a joint_state
    recorder on `recorder_machine`."""
    cluster.start_coordinator()
    cluster.start_daemon(BODY_MACHINE)
    cluster.start_daemon(PROMPT_MACHINE)
    descriptor = dataflow_copy({"SO101_MODE": "direct", "SO101_LANG": "en"}, CLUSTER_DATAFLOW)
    descriptor["nodes"].append({
        "id": "recorder", "path": str(RECORDER), "deploy": {"machine": recorder_machine},
        "inputs": {"joint_state": "simulation/joint_state"}, "env": {"RECORD_FILE": str(record_file)},
    })
    cluster.start_dataflow(write_dataflow(descriptor, tmp_path / "dataflow_cluster.yml"))


def test_the_course_commands_cross_daemons_and_reach_their_targets(tmp_path):
    record_file = tmp_path / "joint_state.json"
    cluster = Cluster(tmp_path / "cluster")
    try:
        start_with_recorder(cluster, tmp_path, record_file, PROMPT_MACHINE)
        cluster.wait_for_node_log(BODY_MACHINE, "simulation", LOADED_MARKS)
        sent_at, end = type_the_script(
            tmp_path, prompt_env(tmp_path, SO101_DAEMON_PORT=str(cluster.daemon_ports[PROMPT_MACHINE])))
        # Which daemon ran which node: each daemon keeps its nodes' logs in its own folder.
        ran = {machine: {node for node in ("simulation", "recorder") if cluster.node_log(machine, node)}
               for machine in (BODY_MACHINE, PROMPT_MACHINE)}
    finally:
        cluster.stop()
    assert ran == {BODY_MACHINE: {"simulation"}, PROMPT_MACHINE: {"recorder"}}
    # The states the recorder took on daemon `desk` crossed from daemon `arm`; the commands the other way.
    check_the_record(record_file, tmp_path / "poses.json", "pybullet", sent_at, end)
    assert json.loads(record_file.read_text())["samples"]
    assert cluster.leftover_processes() == []


def test_without_the_token_the_cli_and_a_daemon_are_refused(tmp_path):
    with Cluster(tmp_path / "cluster") as cluster:
        cluster.start_coordinator()
        assert cluster.token
        env = cluster.env()
        env.pop("DORA_AUTH_TOKEN")
        env["HOME"] = str(tmp_path)  # not the cluster's, so no token file either
        refused = subprocess.run(["dora", "list"], capture_output=True, text=True, env=env, timeout=30, cwd=tmp_path)
        cluster.token, token = None, cluster.token  # the daemon is started without it
        daemon = cluster.start_daemon("intruder", wait=False)
        time.sleep(3)
        cluster.token = token
        joined = cluster.connected_daemons()
        daemon_log = cluster.log("daemon-intruder")
        assert daemon.poll() is None  # it keeps trying, and is kept out
    assert refused.returncode != 0
    assert (f"authentication failed connecting to coordinator at 127.0.0.1:{cluster.coordinator_port}: "
            "HTTP error: 401 Unauthorized") in refused.stderr
    assert "The coordinator was started with --auth and requires a valid token." in refused.stderr
    assert "intruder" not in joined
    assert "401 Unauthorized" in daemon_log


def test_a_node_placed_on_a_machine_no_daemon_has_is_one_clear_line(tmp_path):
    with Cluster(tmp_path / "cluster") as cluster:
        cluster.start_coordinator()
        cluster.start_daemon("arm2")  # a typo in the machine id
        cluster.start_daemon(PROMPT_MACHINE)
        with pytest.raises(ClusterError) as failed:
            cluster.start_dataflow(write_dataflow(dataflow_copy({"SO101_MODE": "direct"}, CLUSTER_DATAFLOW),
                                                  tmp_path / "dataflow_cluster.yml"))
    message = str(failed.value)
    assert "\n" not in message and message.startswith("dora start failed: ")
    assert message == "dora start failed: no matching daemon for machine id `arm`"


def test_the_cluster_dataflow_is_the_courses_dataflow_with_placements():
    import yaml

    from tests.dataflow_helpers import ROOT

    cluster_nodes = yaml.safe_load(CLUSTER_DATAFLOW.read_text())["nodes"]
    placements = {node["id"]: node.pop("deploy") for node in cluster_nodes}
    assert placements == {"keyboard_control": {"machine": PROMPT_MACHINE}, "simulation": {"machine": BODY_MACHINE}}
    assert cluster_nodes == yaml.safe_load((ROOT / "dataflow.yml").read_text())["nodes"]


def test_when_the_simulations_daemon_dies_the_prompt_says_so_in_one_line(tmp_path):
    import signal

    cluster = Cluster(tmp_path / "cluster")
    try:
        cluster.start_coordinator()
        cluster.start_daemon(BODY_MACHINE)
        cluster.start_daemon(PROMPT_MACHINE)
        cluster.start_dataflow(write_dataflow(dataflow_copy({"SO101_MODE": "direct", "SO101_LANG": "en"}, CLUSTER_DATAFLOW),
                                              tmp_path / "dataflow_cluster.yml"))
        prompt = subprocess.Popen(
            PROMPT_COMMAND, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            env=prompt_env(tmp_path, SO101_DAEMON_PORT=str(cluster.daemon_ports[PROMPT_MACHINE])),
        )
        cluster.wait_for_node_log(BODY_MACHINE, "simulation", LOADED_MARKS)
        prompt.stdin.write("0 45\n")
        prompt.stdin.flush()
        time.sleep(2)
        os.killpg(cluster.processes[f"daemon-{BODY_MACHINE}"].pid, signal.SIGKILL)  # the arm's machine goes away
        time.sleep(3)
        started = time.monotonic()
        prompt.stdin.write("0 -45\nstate\nquit\n")
        prompt.stdin.close()
        output = prompt.stdout.read()
        assert prompt.wait(20) == 0
        took_s = time.monotonic() - started
        coordinator_log = cluster.log("coordinator")
    finally:
        cluster.stop()
    replies = output.split("> 0 -45\n", 1)[1].splitlines()
    silent = r"  no joint_state for \d+ s: the simulation \(or the arm's driver\), its machine or the network is gone; not sent"
    assert re.fullmatch(silent, replies[0]) and re.fullmatch(silent, replies[2]), output  # `0 -45`, then `state`
    assert replies[3:] == ["> quit", "  bye"]
    assert took_s < 10  # no hang
    assert cluster.leftover_processes() == []  # the simulation its daemon left behind was stopped too
    assert re.search(rf"Daemon `{BODY_MACHINE}-[0-9a-f-]+` exited", re.sub(r"\x1b\[[0-9;]*m", "", coordinator_log))


def test_when_the_prompts_daemon_dies_the_simulation_goes_on(tmp_path):
    """What the README says of the prompt's machine dropping out, in dora 1.1: the simulation keeps
    publishing; a daemon started again rejoins the coordinator, but not the running dataflow."""
    import signal

    record_file = tmp_path / "joint_state.json"
    cluster = Cluster(tmp_path / "cluster")
    try:
        start_with_recorder(cluster, tmp_path, record_file, BODY_MACHINE)
        env = prompt_env(tmp_path, SO101_DAEMON_PORT=str(cluster.daemon_ports[PROMPT_MACHINE]))
        first = subprocess.Popen(PROMPT_COMMAND, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL, text=True, env=env)
        cluster.wait_for_node_log(BODY_MACHINE, "simulation", LOADED_MARKS)
        first.stdin.write("0 45\n")
        first.stdin.flush()
        time.sleep(2)
        os.killpg(cluster.processes[f"daemon-{PROMPT_MACHINE}"].pid, signal.SIGKILL)
        killed_at = time.monotonic()
        first.kill()
        first.wait()
        time.sleep(2)
        cluster.start_daemon(PROMPT_MACHINE)  # the laptop comes back: its daemon rejoins the coordinator
        time.sleep(3)
        second = subprocess.run(PROMPT_COMMAND, input="0 -45\n", capture_output=True, text=True, env=env, timeout=60)
        cluster.cli("stop", "--name", "so101", timeout_s=30)
    finally:
        cluster.stop()
    samples = json.loads(record_file.read_text())["samples"]
    alone = [state for t, state in samples if killed_at < t < killed_at + 2.0]
    assert len(alone) >= 0.8 * 2.0 * 250  # the simulation went on at its 250 Hz on its own daemon
    assert all(abs(state[0] - 45.0) <= 1.0 for state in alone)  # holding the first prompt's target
    assert second.returncode == 1
    assert "no node with ID `keyboard_control`" in second.stderr
    assert cluster.leftover_processes() == []  # dora 1.1 does not hand the dataflow back
