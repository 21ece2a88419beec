"""The dataflow on a dora cluster: a coordinator with token authentication and two daemons on
127.0.0.1 under different machine ids (so101/runtime/cluster.py, as `so101 cluster-demo` runs it)."""

from __future__ import annotations

import json
import re
import os
import subprocess
import sys
import time

import pytest

from so101.bodies.registry import BODIES
from so101.runtime.cluster import (BODY_MACHINE, CLUSTER_DATAFLOW, PROMPT_MACHINE, Cluster, ClusterError, cluster_dataflow,
                          placed_dataflow)
from so101.runtime.dataflow import LOADED_MARKS, dataflow_copy, write_dataflow
from tests.helpers.dataflow import (
    PROMPT_COMMAND, RECORDER, ROOT, check_the_record, error_lines, prompt_env, run_so101, type_the_script,
)
from tests.helpers.network import on_the_machines_network

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

    cluster_nodes = yaml.safe_load(CLUSTER_DATAFLOW.read_text())["nodes"]
    placements = {node["id"]: node.pop("deploy") for node in cluster_nodes}
    assert placements == {"keyboard_control": {"machine": PROMPT_MACHINE}, "simulation": {"machine": BODY_MACHINE}}
    assert cluster_nodes == yaml.safe_load((ROOT / "dataflow.yml").read_text())["nodes"]
    # What `so101 cluster-dataflow` writes (and cluster-demo starts) is this file with absolute paths.
    assert placed_dataflow(BODIES["pybullet"], {}) == dataflow_copy({}, CLUSTER_DATAFLOW)


def test_cluster_dataflow_writes_the_real_arm_placed_with_paths_on_the_arms_machine(tmp_path):
    import yaml

    written = tmp_path / "cluster.yml"
    result = run_so101("cluster-dataflow", "--body", "real", "--port", "/dev/ttyUSB0", "--calibration",
                       "/home/pi/arm.json", "--root", "/home/pi/so101", "--lang", "en", "--output", str(written))
    assert result.returncode == 0, result.stderr
    assert result.stdout == f"wrote {written}: start it with `dora start {written} --name so101 --detach`\n"
    nodes = {node["id"]: node for node in yaml.safe_load(written.read_text())["nodes"]}
    assert nodes["arm"]["deploy"] == {"machine": BODY_MACHINE}
    assert nodes["arm"]["path"] == "/home/pi/so101/nodes/arm_node.py"
    assert (nodes["arm"]["env"]["SO101_PORT"], nodes["arm"]["env"]["SO101_CALIBRATION"],
            nodes["arm"]["env"]["SO101_LANG"]) == ("/dev/ttyUSB0", "/home/pi/arm.json", "en")
    assert nodes["keyboard_control"]["deploy"] == {"machine": PROMPT_MACHINE}
    assert nodes["keyboard_control"]["path"] == "dynamic"
    assert written.read_text().startswith("# Written from dataflow_real.yml;")


@pytest.mark.parametrize("args, message", [
    (["--body", "real", "--port", "/dev/ttyACM0", "--calibration", "arm.json"],
     "--calibration must be an absolute path on the arm's machine, not 'arm.json'"),
    (["--root", "so101"], "--root must be an absolute path on the arm's machine, not 'so101'"),
    (["--body", "real"], "--body real needs --port PORT and --calibration FILE (no arm? `so101 fake-arm` emulates "
                         "one; `so101 calibrate` makes the file)"),
    (["--port", "/dev/ttyACM0"], "--port and --calibration are for --body real, not pybullet"),
])
def test_cluster_dataflow_refuses_bad_settings_in_one_line(tmp_path, args, message):
    result = run_so101("cluster-dataflow", "--output", str(tmp_path / "cluster.yml"), *args)
    assert result.returncode == 2
    assert error_lines(result.stderr) == [f"so101 cluster-dataflow: {message}"]
    assert not (tmp_path / "cluster.yml").exists()


def test_dora_does_not_find_a_placed_node_by_a_relative_path(tmp_path):
    """Why `so101 cluster-dataflow` makes node paths absolute: dataflow_cluster.yml as it is (paths
    relative to the project) fails in dora 1.1, even started from the project's folder."""
    with Cluster(tmp_path / "cluster") as cluster:
        cluster.start_coordinator()
        cluster.start_daemon(BODY_MACHINE)
        cluster.start_daemon(PROMPT_MACHINE)
        result = subprocess.run(["dora", "start", "dataflow_cluster.yml", "--name", "so101", "--detach"],
                                capture_output=True, text=True, env=cluster.env(),
                                cwd=ROOT, timeout=60)
    assert result.returncode != 0
    assert "failed to prepare node simulation" in result.stderr


def test_a_prompt_whose_daemon_runs_no_dataflow_is_told_to_start_one(tmp_path):
    with Cluster(tmp_path / "cluster") as cluster:
        cluster.start_coordinator()
        cluster.start_daemon(PROMPT_MACHINE)
        prompt = subprocess.run(PROMPT_COMMAND, input="quit\n", capture_output=True, text=True, timeout=60,
                                env=prompt_env(tmp_path, SO101_DAEMON_PORT=str(cluster.daemon_ports[PROMPT_MACHINE])))
    assert prompt.returncode == 1
    assert prompt.stderr.count("\n") == 1 and prompt.stderr.startswith(
        "cannot join the dataflow as keyboard_control (this daemon has no dataflow with a keyboard_control in it: "
        "start one (`dora run dataflow.yml`, or `dora start` on a cluster);")


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


def test_when_the_prompts_daemon_dies_the_simulation_goes_on_and_a_restart_lets_a_new_prompt_drive(tmp_path):
    """What docs/clusters.md says of the prompt's machine dropping out, in dora 1.1: the simulation keeps
    publishing; a daemon started again rejoins the coordinator, but not the running dataflow, so a
    new prompt is refused, in one line that says what to do; after `dora restart so101` a new
    prompt drives the arm again."""
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
        refused = subprocess.run(PROMPT_COMMAND, input="0 -45\n", capture_output=True, text=True, env=env, timeout=60)
        restart = cluster.cli("restart", "so101", timeout_s=60)
        # The first dataflow's recorder wrote its record on the way out; the new one writes at the end.
        deadline = time.monotonic() + 20
        while not record_file.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        before_restart = json.loads(record_file.read_text())["samples"]
        record_file.unlink()
        again = subprocess.Popen(PROMPT_COMMAND, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT, text=True, env=env)
        cluster.wait_for_node_log(BODY_MACHINE, "simulation", LOADED_MARKS)
        sent_at = time.monotonic()
        output, _ = again.communicate("0 -45\n", timeout=60)
        time.sleep(3)
        cluster.cli("stop", "--name", "so101", timeout_s=30)
    finally:
        cluster.stop()
    alone = [state for t, state in before_restart if killed_at < t < killed_at + 2.0]
    assert len(alone) >= 0.8 * 2.0 * 250  # the simulation went on at its 250 Hz on its own daemon
    assert all(abs(state[0] - 45.0) <= 1.0 for state in alone)  # holding the first prompt's target
    assert refused.returncode == 1
    refusal = refused.stderr.strip()
    assert "\n" not in refusal and refusal.endswith("no node with ID `keyboard_control`")
    assert refusal.startswith(
        "cannot join the dataflow as keyboard_control (this daemon has no dataflow with a keyboard_control in it: "
        "start one (`dora run dataflow.yml`, or `dora start` on a cluster); if one runs, this machine's daemon was "
        "started again after it dropped out, and dora 1.1 does not hand a running dataflow back: `dora restart so101` "
        "starts it anew): ")
    assert restart.returncode == 0 and "dataflow restarted" in restart.stdout, restart.stderr
    assert "> 0 -45" in output and again.returncode == 0, output
    after = [state for t, state in json.loads(record_file.read_text())["samples"] if t > sent_at + 2.0]
    assert after and all(abs(state[0] - (-45.0)) <= 1.0 for state in after)  # the new prompt drove it
    assert cluster.leftover_processes() == []


OTHER_DORA_VERSION = "1.0.0"


@pytest.fixture(scope="module")
def other_dora(tmp_path_factory):
    """dora-rs-cli 1.0.0, in an environment of its own: a dora that dora 1.1 accepts next to itself."""
    venv = tmp_path_factory.mktemp("other-dora") / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    subprocess.run([str(venv / "bin" / "pip"), "install", "-q", f"dora-rs-cli=={OTHER_DORA_VERSION}"],
                   check=True, capture_output=True, timeout=600, preexec_fn=on_the_machines_network())
    return venv / "bin" / "dora"


@pytest.mark.parametrize("machine", [BODY_MACHINE, PROMPT_MACHINE])
def test_a_daemon_of_another_dora_version_is_named_in_one_line(tmp_path, other_dora, machine):
    """dora 1.1 lets a 1.0.0 daemon join and run this project's nodes; the node it would run says why not."""
    cluster = Cluster(tmp_path / "cluster")
    try:
        cluster.start_coordinator()
        for machine_id in (BODY_MACHINE, PROMPT_MACHINE):
            cluster.start_daemon(machine_id, dora=str(other_dora) if machine_id == machine else None)
        cluster.start_dataflow(cluster_dataflow(tmp_path, {"SO101_MODE": "direct", "SO101_LANG": "en"}, BODIES["pybullet"]))
        prompt = subprocess.Popen(
            PROMPT_COMMAND, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            env=prompt_env(tmp_path, SO101_DAEMON_PORT=str(cluster.daemon_ports[PROMPT_MACHINE])),
        )
        if machine == BODY_MACHINE:
            cluster.wait_for_node_log(BODY_MACHINE, "simulation", ["cannot start"])
        _, prompt_errors = prompt.communicate("quit\n", timeout=60)
        simulation_log = cluster.node_log(BODY_MACHINE, "simulation")
    finally:
        cluster.stop()
    problem = (f"the dora daemon this node runs under ({other_dora}) is version {OTHER_DORA_VERSION}, this node's "
               "dora-rs is 1.1.0: use one dora version on every machine (this project pins 1.1.0: start the daemon "
               "with this project's .venv/bin/dora, or pip install 'dora-rs-cli==1.1.0' where it runs)")
    if machine == BODY_MACHINE:
        messages = [json.loads(line)["msg"] for line in simulation_log.splitlines() if line.startswith("{")]
        assert f"[simulation] cannot start: {problem}" in messages
    else:
        assert prompt.returncode == 1
        assert prompt_errors.strip() == f"keyboard_control: {problem}"
        assert "cannot start" not in simulation_log
    assert cluster.leftover_processes() == []


def test_the_cli_waits_out_the_coordinators_429_and_gives_up_after_its_time(tmp_path, monkeypatch):
    """dora 1.1's coordinator answers `429 Too Many Requests` to a client off loopback that connects often
    (seen across the sealed rig's tunnel: 20 connections, then none for over a minute)."""
    import so101.runtime.cluster as cluster_module

    limited = subprocess.CompletedProcess([], 1, "", "failed to connect to coordinator at 10.101.0.1:6013: HTTP error: "
                                                     "429 Too Many Requests")
    answers = [limited, limited, subprocess.CompletedProcess([], 0, "arm-01\n", "")]
    calls = []
    monkeypatch.setattr(cluster_module, "RATE_LIMITED_RETRY_S", 0.0)
    monkeypatch.setattr(cluster_module.subprocess, "run", lambda *args, **kwargs: calls.append(args) or answers.pop(0))
    cluster = Cluster.joined(tmp_path, "10.101.0.1", 6013)
    assert cluster.cli("list").stdout == "arm-01\n" and len(calls) == 3
    monkeypatch.setattr(cluster_module, "RATE_LIMITED_S", 0.0)
    answers[:] = [limited, limited]
    assert cluster.cli("list") is limited and len(calls) == 4
