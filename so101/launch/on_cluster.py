"""Where a command's dataflow runs on a dora cluster someone runs: `--coordinator ADDR[:PORT]`, `--machine ID`
(this machine's daemon), `--root FOLDER` (the project's folder on the other machines) and `--policy-machine NAME`
(the daemon that runs the policy node), checked against the daemons the coordinator lists before anything starts.

`so101 eval` and `so101 demos` place their lockstep runs with it (so101.launch.lockstep), `so101 teleop` its body,
prompt and policy (so101.launch.beside_prompt); `placed` puts a `deploy:` on every node of a dataflow.
"""

from __future__ import annotations

import argparse
import subprocess
from dataclasses import dataclass
from pathlib import Path, PurePath

from so101.runtime.cluster import Cluster, ClusterError
from so101.runtime.dataflow import ROOT

DEFAULT_COORDINATOR_PORT = 6013


@dataclass(frozen=True)
class ClusterPlace:
    """A dora cluster someone runs (`--coordinator`): where its coordinator is, the machine id of
    this machine's daemon (`--machine`: what reads or writes this machine's files runs there), the
    project's folder on the other machines (`--root`), and the daemon that runs the policy
    (`--policy-machine`; None: wherever the command puts its driver)."""

    coordinator_addr: str
    coordinator_port: int
    here: str
    root: PurePath = ROOT
    policy_machine: str | None = None


def add_policy_machine_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--policy-machine", default=None, metavar="NAME",
                        help="with --policy and --coordinator: the machine id of the daemon that runs the policy node "
                             "(under --policy-python, a path on that machine; the policy folder and the project at "
                             "the same paths there, or the project under --root)")


def cluster_place(args: argparse.Namespace, here_runs: str) -> ClusterPlace | str | None:
    """The cluster that --coordinator, --machine, --root and --policy-machine name (`here_runs`: what runs on
    --machine, for the line that asks for it); None for none; what is wrong, in one line."""
    policy_machine = getattr(args, "policy_machine", None)
    if args.coordinator is None:
        if policy_machine:
            return (f"--policy-machine {policy_machine} goes with --coordinator ADDR[:PORT] and --machine ID: the "
                    "cluster whose daemon runs the policy")
        return "--machine and --root go with --coordinator ADDR[:PORT]" if args.machine or args.root else None
    if not args.machine:
        return f"--coordinator needs --machine ID: the machine id of this machine's daemon, where {here_runs}"
    addr, _, port = (args.coordinator.rpartition(":") if ":" in args.coordinator
                     else (args.coordinator, "", str(DEFAULT_COORDINATOR_PORT)))
    if not addr or not port.isdigit() or not 0 < int(port) < 65536:
        return f"--coordinator {args.coordinator!r} is not ADDR[:PORT] (e.g. 192.168.1.10 or 192.168.1.10:6013)"
    return ClusterPlace(addr, int(port), args.machine, args.root or ROOT, policy_machine)


def joined_cluster(place: ClusterPlace, work_dir: Path) -> tuple[Cluster, list[str]]:
    """The cluster at `place` (its token in DORA_AUTH_TOKEN) and the machine ids of its daemons, sorted;
    ClusterError in one line when the coordinator does not answer, or has no daemon --machine or
    --policy-machine names."""
    cluster = Cluster.joined(work_dir, place.coordinator_addr, place.coordinator_port)
    where = f"{place.coordinator_addr}:{place.coordinator_port}"
    try:
        machines = sorted(set(cluster.connected_daemons()))
    except (OSError, subprocess.TimeoutExpired) as error:
        raise ClusterError(f"the coordinator at {where} did not answer: {error}") from None
    for option, machine in (("--machine", place.here), ("--policy-machine", place.policy_machine)):
        if machine is not None and machine not in machines:
            raise ClusterError(f"no daemon with machine id {machine!r} on the coordinator at {where}, for {option} "
                               f"(its daemons: {', '.join(machines) or 'none'}; is DORA_AUTH_TOKEN its token?)")
    return cluster, machines


def placed(descriptor: dict, here: str, elsewhere: dict[str, str]) -> dict:
    """`descriptor` with every node on machine `here` but those `elsewhere` names (node id -> machine id)."""
    return {**descriptor, "nodes": [{"deploy": {"machine": elsewhere.get(node["id"], here)}, **node}
                                    for node in descriptor["nodes"]]}
