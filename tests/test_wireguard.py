"""The sealed cluster's plain parts (so101/runtime/wireguard.py): which machines, their tunnel
addresses, the WireGuard files and the command lines; and `so101 cluster-dataflow --sealed` as a
user runs it. The cluster itself, sealed, runs in tests/test_two_machines.py."""

from __future__ import annotations

import os
import re
import shutil
import stat
import subprocess

import pytest

from so101.runtime.wireguard import (
    Machine, SealError, daemon_command, parse_machines, wireguard_text, write_wireguard_files,
)
from so101.runtime.venv import BIN as VENV_BIN
from tests.helpers.dataflow import ROOT, error_lines, run_so101

NEEDS_WG = pytest.mark.skipif(shutil.which("wg") is None, reason="no `wg` (wireguard-tools) to make keys")
ARM_DESK = ("arm", "desk")


def test_machines_get_tunnel_addresses_in_order_the_coordinators_first():
    machines = parse_machines("desk, gpu=192.168.1.30 ,arm=192.168.1.10", "arm", ARM_DESK)
    assert machines == [Machine("arm", "192.168.1.10", "10.101.0.1"), Machine("desk", None, "10.101.0.2"),
                        Machine("gpu", "192.168.1.30", "10.101.0.3")]
    assert [machine.interface for machine in machines] == ["so101-arm", "so101-desk", "so101-gpu"]


@pytest.mark.parametrize("spec, said", [
    ("arm,desk", "machine 'arm' runs the coordinator, so the others must reach it: give its address on the lab "
                 "network, e.g. arm=192.168.1.10"),
    ("arm=192.168.1.10", "name the machine desk (e.g. arm=192.168.1.10,desk), not 'arm=192.168.1.10'"),
    ("gpu=1.2.3.4", "name the machines arm and desk (e.g. arm=192.168.1.10,desk), not 'gpu=1.2.3.4'"),
    ("arm=192.168.1.x,desk", "'192.168.1.x' (machine 'arm') is not an IP address, e.g. arm=192.168.1.10"),
    ("arm=1.2.3.4,desk,laptop2", "machines 'desk' and 'laptop2' both have no address, so WireGuard cannot join them: "
                                 "give one its address (NAME=IP)"),
    ("arm=1.2.3.4,desk,desk", "machine 'desk' is named twice in 'arm=1.2.3.4,desk,desk'"),
    ("arm=1.2.3.4,Desk", "'Desk' is not a machine id: 1 to 9 lower-case letters, digits or _, as in arm=192.168.1.10,desk"),
    ("arm=1.2.3.4,desk,workstation", "'workstation' is not a machine id: 1 to 9 lower-case letters, digits or _, as in "
                                     "arm=192.168.1.10,desk"),
])
def test_machines_that_cannot_be_sealed_are_refused_in_one_line(spec, said):
    with pytest.raises(SealError) as refused:
        parse_machines(spec, "arm", ARM_DESK)
    assert str(refused.value) == said


def test_each_file_dials_the_machines_with_addresses_and_keeps_its_tunnel_address_to_the_tunnel():
    arm, desk, gpu = parse_machines("arm=192.168.1.10,desk,gpu=fd00::30", "arm", ARM_DESK)
    desk_file = wireguard_text(desk, "DESK-PRIVATE", [(arm, "ARM-PUBLIC"), (gpu, "GPU-PUBLIC")])
    arm_file = wireguard_text(arm, "ARM-PRIVATE", [(desk, "DESK-PUBLIC"), (gpu, "GPU-PUBLIC")])
    assert "ListenPort" not in desk_file and "ListenPort = 51820" in arm_file
    assert re.findall(r"PublicKey = (\S+)\nAllowedIPs = (\S+)\nEndpoint = (\S+)\nPersistentKeepalive = 25", desk_file) == [
        ("ARM-PUBLIC", "10.101.0.1/32", "192.168.1.10:51820"), ("GPU-PUBLIC", "10.101.0.3/32", "[fd00::30]:51820")]
    # The arm dials the GPU machine, not the laptop (no address); a machine with an address keeps no keepalive.
    assert "Endpoint = [fd00::30]:51820" in arm_file and "Endpoint = 192" not in arm_file
    assert "PersistentKeepalive" not in arm_file
    rule = "INPUT -d 10.101.0.2/32 ! -i %i -m addrtype ! --src-type LOCAL -j DROP"
    assert f"PostUp = iptables -I {rule}\nPreDown = iptables -D {rule}\n" in desk_file
    assert desk_file.count("PrivateKey") == 1 and "DESK-PRIVATE" in desk_file


def test_a_daemon_listens_on_its_tunnel_address_and_dials_every_other_daemon():
    machines = parse_machines("arm=192.168.1.10,desk,gpu=192.168.1.30", "arm", ARM_DESK)
    assert " ".join(daemon_command(machines[2], machines)) == (
        "dora daemon --machine-id gpu --coordinator-addr 10.101.0.1 --coordinator-port 6013 --zenoh-listen "
        "10.101.0.3:7447 --zenoh-connect tcp/10.101.0.1:7447 --zenoh-connect tcp/10.101.0.2:7447 --zenoh-no-multicast")


@NEEDS_WG
def test_the_files_hold_each_machines_private_key_only_and_are_never_written_over(tmp_path):
    machines = parse_machines("arm=192.168.1.10,desk,gpu=192.168.1.30", "arm", ARM_DESK)
    paths = write_wireguard_files(tmp_path / "wg", machines)
    assert [path.name for path in paths] == ["so101-arm.conf", "so101-desk.conf", "so101-gpu.conf"]
    texts = [path.read_text() for path in paths]
    privates = [re.search(r"PrivateKey = (\S+)", text).group(1) for text in texts]
    publics = [subprocess.run(["wg", "pubkey"], input=key, capture_output=True, text=True, check=True).stdout.strip()
               for key in privates]
    for index, (path, text) in enumerate(zip(paths, texts)):
        assert stat.S_IMODE(path.stat().st_mode) == 0o600
        assert sorted(re.findall(r"PublicKey = (\S+)", text)) == sorted(publics[:index] + publics[index + 1:])
        assert not any(other in text for other in privates[:index] + privates[index + 1:])
    with pytest.raises(SealError, match=r"so101-arm.conf exists: keys are never written over; remove it, or give "
                                        r"another --wireguard-dir"):
        write_wireguard_files(tmp_path / "wg", machines)
    assert [path.read_text() for path in paths] == texts


@NEEDS_WG
def test_cluster_dataflow_sealed_prints_the_steps_the_docs_give(tmp_path):
    done = run_so101("cluster-dataflow", "--lang", "en", "--sealed", "arm=192.168.1.10,desk", "--wireguard-dir",
                     str(tmp_path / "so101-wireguard"), "-o", str(tmp_path / "placed_dataflow.yml"))
    assert done.returncode == 0, done.stderr
    assert sorted(path.name for path in (tmp_path / "so101-wireguard").iterdir()) == ["so101-arm.conf", "so101-desk.conf"]
    commands = [line.strip() for line in done.stdout.splitlines() if line.strip().startswith(("sudo ", "dora "))]
    assert len(commands) == 5
    docs = (ROOT / "docs" / "clusters-sealed.md").read_text()
    for command in commands:  # as the docs show them, the files and the dataflow in the current folder
        assert command.replace(f"{tmp_path}/", "") in docs, command


@pytest.mark.parametrize("args, said", [
    (["--sealed", "arm,desk", "-o", "x.yml"], "so101 cluster-dataflow: --sealed: machine 'arm' runs the coordinator, "
                                             "so the others must reach it: give its address on the lab network, "
                                             "e.g. arm=192.168.1.10"),
    (["--sealed", "arm=192.168.1.10,desk"], "so101 cluster-dataflow: --sealed writes files: give the dataflow's too, "
                                            "with -o FILE"),
])
def test_cluster_dataflow_sealed_refuses_in_one_line(args, said):
    done = run_so101("cluster-dataflow", *args)
    assert done.returncode == 2 and error_lines(done.stderr) == [said]


@pytest.mark.parametrize("command", [pytest.param(["cluster-demo", "--sealed"], marks=pytest.mark.skipif(
                                         os.geteuid() != 0, reason="as a user it first asks for root")),
                                     ["cluster-dataflow", "--sealed", "arm=192.168.1.10,desk", "-o", "x.yml"]])
def test_without_wireguard_the_sealed_commands_say_how_to_get_it(tmp_path, command):
    # A PATH with this project's venv and iproute2's and iptables' folder, but no wg (it is in /usr/bin).
    done = run_so101(*command, "--lang", "en", PATH=f"{VENV_BIN}:/usr/sbin:/sbin")
    said = ("WireGuard's tools are not installed: `sudo apt-get install wireguard-tools wireguard-go` (Debian, Ubuntu), "
            "or wireguard-tools with the kernel's WireGuard module")
    prefix = "so101 cluster-demo --sealed: " if command[0] == "cluster-demo" else "so101 cluster-dataflow: --sealed: "
    assert done.returncode == 2 and error_lines(done.stderr) == [prefix + said]
