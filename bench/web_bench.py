"""The web view's cost to the body (`so101 bench`): five viewers on its page while the arm moves.

The body's dataflow runs as `so101 teleop --web` runs it (so101.runtime.dataflow.with_web_view),
with bench/nodes/prober.py in the prompt's place moving the arm every 75 ms (PACED_PROBE_ENV).
Once the web view serves, VIEWERS viewers connect, in two runs:
  - "sockets": viewers elsewhere. Each is the page's websocket without the page: it connects as
    viser's client does and reads every message, which is all a browser on another machine costs
    this one. Counted: the messages each receives a second.
  - "browsers": headless Chromiums on this machine (bench/browser.py: WebGL on SwiftShader, every
    host but 127.0.0.1 unreachable), under SCHED_IDLE. On a machine with no GPU each page draws
    with the CPU the body needs: this run says what that costs. Counted in each page: the angle
    text's updates and the frames it drew, a second.
Over the window that starts once every viewer is connected: the body's joint_state/s, ticks missed
and simulated/wall time (its tick log), and the web view node's CPU and RSS at the window's start
and end (a long --duration shows whether its memory grows).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import socket
import threading
import time
from pathlib import Path

from bench.browser import CHROMIUM, Browser
from bench.common import PACED_PROBE_ENV, WARMUP_S, run_dataflow, states_per_s, target_row, tick_figures
from so101.bodies.registry import BODIES
from so101.runtime.dataflow import TICK_PERIOD_S, with_web_view
from so101.runtime.processes import processes_with_env

VIEWERS = 5
READY_TIMEOUT_S = 120.0
# In each page: the angle text's changes and the frames drawn (requestAnimationFrame).
PAGE_COUNTERS = """(() => {
  window.__so101 = {angleUpdates: 0, frames: 0, angles: ""};
  new MutationObserver(() => {
    const match = document.body.textContent.match(/shoulder_pan: [^°]*°/);
    const angles = match ? match[0] : "";
    if (angles !== window.__so101.angles) { window.__so101.angles = angles; window.__so101.angleUpdates++; }
  }).observe(document.body, {subtree: true, childList: true, characterData: true});
  const frame = () => { window.__so101.frames++; requestAnimationFrame(frame); };
  requestAnimationFrame(frame);
})()"""
PAGE_COUNTS = "[window.__so101.angleUpdates, window.__so101.frames]"


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of `pid` so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError(f"no VmRSS for {pid}")


class SocketViewer:
    """The page's websocket without the page, reading every message on a thread of its own."""

    def __init__(self, web_port: int):
        import viser

        # viser refuses a client whose subprotocol does not name its version.
        self.url, self.protocol = f"ws://127.0.0.1:{web_port}/", f"viser-v{viser.__version__}"
        self.messages = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=lambda: asyncio.run(self._read()), daemon=True)
        self._thread.start()

    async def _read(self) -> None:
        import websockets

        async with websockets.connect(self.url, subprotocols=[self.protocol], max_size=None) as connection:
            while not self._stop.is_set():
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(connection.recv(), 0.2)
                    self.messages += 1

    def counts(self) -> list[int]:
        return [self.messages]

    def reset(self) -> None:
        self.messages = 0

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)


class PageViewer:
    """A headless Chromium on the page, at idle priority, counting in the page."""

    def __init__(self, web_port: int):
        self.browser = Browser(free_port(), idle=True)
        self.browser.open(f"http://127.0.0.1:{web_port}/")

    def ready(self) -> None:
        self.browser.wait_for_text("shoulder_pan: ", READY_TIMEOUT_S)
        self.browser.evaluate(PAGE_COUNTERS)

    def counts(self) -> list[int]:
        return list(self.browser.evaluate(PAGE_COUNTS))

    def reset(self) -> None:
        self.browser.evaluate("window.__so101.angleUpdates = 0, window.__so101.frames = 0")

    def close(self) -> None:
        self.browser.kill()


class Viewers:
    """`watch(duration_s)` (run_dataflow's `during`): the viewers connect, then the measured window."""

    def __init__(self, kind: str, web_port: int, dora_log: Path):
        self.kind, self.web_port, self.dora_log = kind, web_port, dora_log
        self.figures: dict = {}

    def _web_view_pid(self) -> int:
        deadline = time.monotonic() + READY_TIMEOUT_S
        while f"web view: http://127.0.0.1:{self.web_port}/" not in self.dora_log.read_text(errors="replace"):
            if time.monotonic() > deadline:
                raise RuntimeError(f"the web view never served (see {self.dora_log})")
            time.sleep(0.1)
        pids = processes_with_env("SO101_WEB_PORT", str(self.web_port))
        if len(pids) != 1:
            raise RuntimeError(f"expected one web view process, found {pids}")
        return pids[0]

    def watch(self, duration_s: float) -> None:
        pid = self._web_view_pid()
        viewers: list[SocketViewer | PageViewer] = []
        try:
            for _ in range(VIEWERS):
                viewers.append(SocketViewer(self.web_port) if self.kind == "sockets" else PageViewer(self.web_port))
            for viewer in viewers:
                if isinstance(viewer, PageViewer):
                    viewer.ready()
            time.sleep(WARMUP_S)
            for viewer in viewers:
                viewer.reset()
            start_ns, cpu_start, rss_start = time.monotonic_ns(), cpu_seconds(pid), rss_mb(pid)
            time.sleep(duration_s)
            end_ns, cpu_end, rss_end = time.monotonic_ns(), cpu_seconds(pid), rss_mb(pid)
            counts = [viewer.counts() for viewer in viewers]
        finally:
            for viewer in viewers:
                viewer.close()
        window_s = (end_ns - start_ns) / 1e9
        self.figures = {
            "window_ns": [start_ns, end_ns],
            "web_view_cpu_percent": 100 * (cpu_end - cpu_start) / window_s,
            "web_view_rss_mb": {"start": rss_start, "end": rss_end},
            # One figure per viewer: messages (sockets); angle text updates and frames drawn (browsers).
            "per_viewer_per_s": [[count / window_s for count in each] for each in counts],
        }


def measure(work_dir: Path, duration_s: float, body: str, kind: str) -> dict:
    run_dir = work_dir / f"web-{kind}"
    web_port = free_port()
    viewers = Viewers(kind, web_port, run_dir / "dora.log")

    def add_web_view(descriptor: dict) -> None:
        with_web_view(descriptor, BODIES[body].node_id, {"SO101_WEB_PORT": str(web_port)})

    print(f"dora run with the web view, {VIEWERS} {kind} on its page, {duration_s:g} s ...", flush=True)
    record = run_dataflow(run_dir, duration_s, {"SO101_FAST_STEPS": "0"}, PACED_PROBE_ENV, body=body,
                          extend=add_web_view, during=viewers.watch)
    start_ns, end_ns = viewers.figures.pop("window_ns")
    ticks = tick_figures([tick for tick in record["ticks"] if start_ns <= tick[0] <= end_ns], TICK_PERIOD_S)
    per_s, span_s = states_per_s(record["probe"]["states"], start_ns, end_ns)
    return {**viewers.figures, "joint_state_per_s": per_s, "measured_s": span_s,
            "sim_over_wall": ticks["steps_per_s"] * TICK_PERIOD_S, "ticks_missed": ticks["ticks_missed"]}


def run_web_benchmark(work_dir: Path, duration_s: float, body: str, browsers: bool = True) -> dict:
    """Both runs, `duration_s` each; the browsers' is skipped, saying why, without chromium or `browsers`."""
    figures = {"viewers": VIEWERS, "sockets": measure(work_dir, duration_s, body, "sockets")}
    if not browsers:
        figures["browsers"] = {"skipped": "not in a --quick run"}
    elif CHROMIUM is None:
        figures["browsers"] = {"skipped": "chromium is not installed (Debian: apt-get install chromium)"}
    else:
        figures["browsers"] = measure(work_dir, duration_s, body, "browsers")
    return figures


def targets(figures: dict, joint_state_per_s: float, sim_over_wall_error: float) -> list[dict]:
    """The body's pace with the viewers elsewhere: what the web view itself costs it."""
    sockets = figures["sockets"]
    rate, ratio = sockets["joint_state_per_s"], sockets["sim_over_wall"]
    return [
        target_row(f"joint_state per s, {figures['viewers']} viewers on the web view", rate,
                   f">= {joint_state_per_s}", rate >= joint_state_per_s),
        target_row(f"simulated / wall time, {figures['viewers']} viewers on the web view", ratio,
                   f"1 ± {sim_over_wall_error}", abs(ratio - 1) <= sim_over_wall_error),
    ]


def table_lines(figures: dict, label_width: int = 52) -> list[str]:
    def row(label: str, value: str = "") -> str:
        return f"{label:<{label_width}} {value}".rstrip()

    def body_rows(run: dict) -> list[str]:
        rss = run["web_view_rss_mb"]
        return [
            row("  joint_state per s | simulated / wall time", f"{run['joint_state_per_s']:>10.2f} | {run['sim_over_wall']:.4f}"),
            row("  ticks missed", f"{run['ticks_missed']:>10d}"),
            row("  web view node: CPU % | RSS start -> end (MB)",
                f"{run['web_view_cpu_percent']:>10.1f} | {rss['start']:.1f} -> {rss['end']:.1f}"),
        ]

    count = figures["viewers"]
    sockets = figures["sockets"]
    messages = [each[0] for each in sockets["per_viewer_per_s"]]
    lines = [row(f"web view, {count} viewers elsewhere (websockets, {sockets['measured_s']:.0f} s)"),
             *body_rows(sockets),
             row("  messages each viewer received per s (min | max)", f"{min(messages):>10.1f} | {max(messages):.1f}")]
    browsers = figures["browsers"]
    if "skipped" in browsers:
        return lines + [row(f"web view, {count} browsers on this machine", f"not measured: {browsers['skipped']}")]
    updates = [each[0] for each in browsers["per_viewer_per_s"]]
    frames = [each[1] for each in browsers["per_viewer_per_s"]]
    return lines + [
        row(f"web view, {count} browsers on this machine (software WebGL, idle priority, {browsers['measured_s']:.0f} s)"),
        *body_rows(browsers),
        row("  each page: angle text updates per s (min | max)", f"{min(updates):>10.1f} | {max(updates):.1f}"),
        row("  each page: frames drawn per s (min | max)", f"{min(frames):>10.1f} | {max(frames):.1f}"),
    ]
