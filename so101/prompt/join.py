"""Joining the running dataflow as a dynamic node, or saying in one line why it cannot.

The reasons go to stderr through logging (`so101.runtime.logs`), each as one bare line.
"""

from __future__ import annotations

import logging

from so101.runtime.dataflow import has_dynamic_node
from so101.runtime.processes import dora_run_dataflow, dora_runs, who_runs
from so101.runtime.versions import (
    DAEMON_DEFAULT_LOCAL_PORT, listening_process, dora_version_mismatch, joined_daemon_version_problem,
)

log = logging.getLogger(__name__)

TEXT = {
    "zh": {
        "join_failed": "无法作为 {node_id} 加入数据流(先在另一个终端运行 `dora run dataflow.yml`;集群上,本机的 "
        "`dora daemon` 须在运行): {error}",
        "join_no_place": "无法作为 {node_id} 加入数据流(此守护进程上没有含 {node_id} 的数据流:请先启动一个(`dora run "
        "dataflow.yml`,集群上用 `dora start`);若数据流已在运行,说明此机器的守护进程掉线后重启过,dora 1.1 不会把运行中的"
        "数据流交还给它:`dora restart so101` 重新启动数据流): {error}",
        "two_dataflows": "无法作为 {node_id} 加入数据流:本机有两个数据流都在等它,而 dora 1.1 只让它加入占着端口 {port} 的那个 "
        "{holder};{others} 在它之后启动,加入不了(dora 曾提示 `Daemon listen port already in use`)。先停掉其中一个"
        "(在它的终端按 Ctrl-C),再启动这里",
    },
    "en": {
        "join_failed": "cannot join the dataflow as {node_id} (start it first in another terminal: "
        "`dora run dataflow.yml`; on a cluster, this machine's `dora daemon` must be running): {error}",
        "join_no_place": "cannot join the dataflow as {node_id} (this daemon has no dataflow with a {node_id} in it: "
        "start one (`dora run dataflow.yml`, or `dora start` on a cluster); if one runs, this machine's daemon was "
        "started again after it dropped out, and dora 1.1 does not hand a running dataflow back: `dora restart so101` "
        "starts it anew): {error}",
        "two_dataflows": "cannot join the dataflow as {node_id}: two dataflows on this machine wait for one, and dora 1.1 "
        "lets it join only the one holding port {port}, {holder}; {others} started after it and cannot be joined "
        "(dora said `Daemon listen port already in use`). Stop one of them (Ctrl-C in its terminal), then start this again",
    },
}


def port_holder(daemon_port: int | None = None) -> int | None:
    """The pid of the dora process a dynamic node joins through `daemon_port` (dora's own port for None)."""
    return listening_process(daemon_port or DAEMON_DEFAULT_LOCAL_PORT)


def unreachable_dataflows(node_id: str, holder: int | None) -> list[int]:
    """The `dora run`s of this machine but `holder` that wait for `node_id` to join: each started while
    another held dora's port, so `node_id` can never reach it (dora 1.1's `dora run` has no other port)."""
    return [pid for pid in dora_runs() if pid != holder and has_dynamic_node(dora_run_dataflow(pid), node_id)]


def two_dataflows_problem(node_id: str, daemon_port: int | None, lang: str) -> str | None:
    """Why `node_id` must not join through dora's own port, in one line: another dataflow that waits
    for it runs beside the one it would join (it would drive the wrong arm); None when it may."""
    if daemon_port not in (None, DAEMON_DEFAULT_LOCAL_PORT):
        return None  # a daemon of its own port (a cluster's): no `dora run` can take it
    holder = port_holder()
    if holder is None:
        return None
    others = unreachable_dataflows(node_id, holder)
    if not others:
        return None
    return TEXT[lang]["two_dataflows"].format(node_id=node_id, port=DAEMON_DEFAULT_LOCAL_PORT, holder=who_runs(holder),
                                              others=", ".join(who_runs(pid) for pid in others))


def join_dataflow(node_id: str, daemon_port: int | None, lang: str):
    """The dora Node `node_id` of the dataflow running on the daemon at `daemon_port` (dora's
    own port for None), or None once the reason is logged."""
    from dora import Node

    two_dataflows = two_dataflows_problem(node_id, daemon_port, lang)
    if two_dataflows:
        log.error("%s", two_dataflows)
        return None
    daemon_problem = joined_daemon_version_problem(daemon_port)
    if daemon_problem:
        log.error("%s: %s", node_id, daemon_problem)
        return None
    try:
        return Node(node_id, daemon_port=daemon_port) if daemon_port else Node(node_id)
    except Exception as error:  # noqa: BLE001 - dora raises a bare RuntimeError with a multi-line chain
        reason = " ".join(str(error).split("Location:")[0].split())  # drop the Rust backtrace
        # dora's answer when no dataflow of this daemon has this node
        text = TEXT[lang]["join_no_place" if "no node with ID" in reason else "join_failed"]
        log.error("%s", text.format(node_id=node_id, error=reason))
        mismatch = dora_version_mismatch()  # the likeliest cause when the dataflow does run
        if mismatch:
            log.error("%s: %s", node_id, mismatch)
        return None
