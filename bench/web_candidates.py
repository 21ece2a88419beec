"""Three ways to see the arm in a browser, measured side by side (issue "See the arm in a browser").

    python3.11 bench/web_candidates.py [--only viser,rerun,meshcat] [--duration 20]
                                       [--scratch /tmp/webcand] [--out bench/results/web-candidates.json]
    (or with the project venv's python: .venv/bin/python bench/web_candidates.py)

Candidates, each in its own fresh venv under the scratch folder (made the first time, reused after):
  viser    pip install viser yourdfpy   -> viser.extras.ViserUrdf, update_cfg() per frame
  rerun    pip install rerun-sdk        -> rr.serve_grpc + rr.serve_web_viewer, the URDF logged with
                                           rr.log_file_from_path, joints as rr.urdf.UrdfJoint.compute_transform
  meshcat  pip install meshcat          -> one StlMeshGeometry per URDF visual in a scene tree that mirrors
                                           the URDF's joints (parsed here with xml.etree), set_transform per joint

For each one: its server script (written to a temp folder) loads assets/SO101/so101_new_calib.urdf and moves the
five arm joints and the gripper on sines at 30 Hz; one headless Chromium (SwiftShader WebGL, every host but
127.0.0.1 unresolvable) opens the page and is driven over the DevTools protocol (a stdlib websocket client below).
Measured: install size (what the candidate adds to a fresh venv's site-packages), requests the page tried to
other hosts (offline), start of the server -> arm drawn (yellow arm pixels in a screenshot), the server's CPU %
and peak RSS (the whole process tree: meshcat's server is a child process) while animating with the browser
connected, the page's requestAnimationFrame/s, frames/s that issued WebGL draw calls, and screencast frames/s
(the compositor sends one per changed picture) with how many were distinct. A screenshot of each page goes to
<scratch>/<name>.png.

Needs: python3.11 with venv, Debian's chromium (apt-get install -y chromium), network to PyPI the first time
(about 1.5 GB of downloads and 1-2 min per venv). Takes about 1 min per candidate once the venvs exist.
Not part of the test suite; nothing imports it. Figures are wall-clock on a shared machine: the load average
is recorded with them.
"""

from __future__ import annotations

import argparse
import base64
import contextlib
import hashlib
import json
import os
import platform
import shutil
import socket
import struct
import subprocess
import sys
import tempfile
import time
import urllib.request
import zlib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script: the checkout holds `bench`
    sys.path.insert(0, str(ROOT))
from bench.browser import FLAGS as BROWSER_FLAGS  # noqa: E402  the tests' headless Chromium, unthrottled
URDF = ROOT / "assets" / "SO101" / "so101_new_calib.urdf"
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser") or "chromium"
VIEW = (960, 540)  # CSS pixels of the page, device scale 1

# -- the candidates' servers ---------------------------------------------------------------------------------
# Each reads URDF and PORT (and PORT2 where it needs two) from its environment, prints "READY <url>" once the
# model is loaded and then moves the arm at 30 Hz until it is stopped.
COMMON = r'''
import math, os, signal, sys, time
from pathlib import Path
signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))  # so atexit handlers (meshcat's child server) run
URDF = Path(os.environ["URDF"])
PORT = int(os.environ["PORT"])
# radians: shoulder_pan, shoulder_lift, elbow_flex, wrist_flex, wrist_roll, gripper
NAMES = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")
def pose(t):
    arm = [0.9 * math.sin(2 * math.pi * 0.25 * t + i * 0.8) for i in range(5)]
    return arm + [0.8 + 0.8 * math.sin(2 * math.pi * 0.5 * t)]
def animate(apply):
    period, start, n = 1 / 30, time.perf_counter(), 0
    while True:
        apply(pose(time.perf_counter() - start))
        n += 1
        delay = start + n * period - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
'''

SERVERS = {
    "viser": COMMON + r'''
import numpy as np, viser
from viser.extras import ViserUrdf
server = viser.ViserServer(host="127.0.0.1", port=PORT, verbose=False)
server.initial_camera.position = (0.45, -0.45, 0.40)
server.initial_camera.look_at = (0.0, 0.0, 0.15)
urdf = ViserUrdf(server, URDF, root_node_name="/so101")
server.scene.add_grid("/grid", width=1.0, height=1.0, cell_size=0.05)
order = [NAMES.index(name) for name in urdf.get_actuated_joint_names()]
print("READY", f"http://127.0.0.1:{PORT}/", flush=True)
animate(lambda q: urdf.update_cfg(np.array([q[i] for i in order])))
''',
    "rerun": COMMON + r'''
import urllib.parse
import rerun as rr
import rerun.urdf as rru
rr.init("so101_web_view")
grpc = rr.serve_grpc(grpc_port=int(os.environ["PORT2"]))
rr.serve_web_viewer(web_port=PORT, open_browser=False, connect_to=grpc)
rr.log_file_from_path(URDF, static=True)
tree = rru.UrdfTree.from_file_path(URDF)
joints = [tree.get_joint_by_name(name) for name in NAMES]
print("READY", f"http://127.0.0.1:{PORT}/?url={urllib.parse.quote(grpc, safe='')}", flush=True)
def apply(q):
    for joint, angle in zip(joints, q):
        rr.log("transforms", joint.compute_transform(angle, clamp=True))
animate(apply)
''',
    "meshcat": COMMON + r'''
import xml.etree.ElementTree as ET
import numpy as np
import meshcat, meshcat.geometry as g, meshcat.transformations as tf
vis = meshcat.Visualizer()
root = ET.parse(URDF).getroot()
colors = {m.get("name"): m.find("color").get("rgba") for m in root.findall("material") if m.find("color") is not None}
def origin(el):
    o = el.find("origin") if el is not None else None
    xyz = [float(v) for v in (o.get("xyz", "0 0 0") if o is not None else "0 0 0").split()]
    rpy = [float(v) for v in (o.get("rpy", "0 0 0") if o is not None else "0 0 0").split()]
    m = tf.euler_matrix(*rpy, axes="sxyz"); m[:3, 3] = xyz
    return m
joints = {j.get("name"): j for j in root.findall("joint")}
parent_of = {j.find("child").get("link"): j for j in joints.values()}
def link_path(link):  # the link's node: /so101/<joint>/<joint>/.../<link>
    parts = [link]
    while link in parent_of:
        j = parent_of[link]; parts += [j.get("name")]; link = j.find("parent").get("link")
    return "/so101/" + "/".join(reversed(parts))
for link in root.findall("link"):
    for i, visual in enumerate(link.findall("visual")):
        mesh = visual.find("geometry/mesh")
        if mesh is None:
            continue
        rgba = [float(v) for v in colors.get(visual.find("material").get("name") if visual.find("material") is not None else "", "0.7 0.7 0.7 1").split()]
        color = (int(rgba[0] * 255) << 16) | (int(rgba[1] * 255) << 8) | int(rgba[2] * 255)
        node = vis[link_path(link.get("name")) + f"/visual_{i}"]
        node.set_object(g.StlMeshGeometry.from_file(str(URDF.parent / mesh.get("filename"))), g.MeshLambertMaterial(color=color))
        node.set_transform(origin(visual))
joint_nodes = {name: vis[link_path(j.find("child").get("link")).rsplit("/", 1)[0]] for name, j in joints.items()}
for name, j in joints.items():
    joint_nodes[name].set_transform(origin(j))
vis["/Cameras/default/rotated/<object>"].set_property("position", [0.6, 0.35, -0.6])  # three.js y-up coordinates
def apply(q):
    for name, angle in zip(NAMES, q):
        j = joints[name]
        axis = [float(v) for v in j.find("axis").get("xyz").split()]
        joint_nodes[name].set_transform(origin(j) @ tf.rotation_matrix(angle, axis))
print("READY", vis.url(), flush=True)
animate(apply)
''',
}

CANDIDATES = {
    "viser": {"pip": ["viser", "yourdfpy"], "import": "viser, yourdfpy"},
    "rerun": {"pip": ["rerun-sdk"], "import": "rerun"},
    "meshcat": {"pip": ["meshcat"], "import": "meshcat"},
}

# What each offers out of the box for the issue (from their APIs: viser.GuiApi/SceneApi, rerun's archetypes
# and views, meshcat.geometry), not measured.
FEATURES = {
    "viser": {
        "orbit_pan_zoom": "yes (three.js camera controls)",
        "joint_angle_text_panel": "yes: gui.add_number/add_text/add_markdown/add_slider in a side panel (sliders can also command)",
        "rolling_plot": "yes: gui.add_uplot (uPlot) / gui.add_plotly; data pushed from Python",
        "image_panel": "yes: gui.add_image (panel) or scene.add_image (in 3D)",
        "marker_label": "yes: scene.add_label, add_icosphere/add_frame/add_arrows, add_transform_controls (drag gizmo)",
    },
    "rerun": {
        "orbit_pan_zoom": "yes (3D view)",
        "joint_angle_text_panel": "partly: rr.TextDocument/TextLog views, or values shown in the selection panel",
        "rolling_plot": "yes: rr.Scalars -> time-series view, plus a timeline to scrub back in time",
        "image_panel": "yes: rr.Image / EncodedImage / VideoStream in a 2D view",
        "marker_label": "yes: labels on Points3D/Boxes3D/Arrows3D; no input widgets (view only, no sliders/buttons)",
    },
    "meshcat": {
        "orbit_pan_zoom": "yes (three.js OrbitControls)",
        "joint_angle_text_panel": "no: only the dat.gui scene-tree panel (visibility, lights); no custom text from Python",
        "rolling_plot": "no",
        "image_panel": "only as an ImageTexture on a plane inside the 3D scene",
        "marker_label": "partly: g.SceneText texture on a plane, spheres/triads as markers",
    },
}


# -- small helpers ---------------------------------------------------------------------------------------------
def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def tree_size_bytes(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file() and not f.is_symlink())


def site_packages(venv: Path) -> Path:
    return next((venv / "lib").glob("python3*/site-packages"))


def freeze(venv: Path) -> list[str]:
    out = subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "list", "--format=freeze"],
                         capture_output=True, text=True, check=True).stdout
    return sorted(line for line in out.split() if line)


def ensure_venv(scratch: Path, name: str) -> dict:
    """The candidate's venv, made and installed the first time; what its install added to site-packages."""
    venv, record = scratch / name, scratch / f"{name}.install.json"
    spec = CANDIDATES[name]
    if record.exists() and (venv / "bin" / "python").exists():
        return json.loads(record.read_text())
    shutil.rmtree(venv, ignore_errors=True)
    subprocess.run([sys.executable if sys.version_info[:2] == (3, 11) else "python3.11", "-m", "venv", str(venv)],
                   check=True)
    base_bytes, base_pkgs = tree_size_bytes(site_packages(venv)), freeze(venv)
    base_dirs = {d.name for d in site_packages(venv).iterdir()}
    started = time.perf_counter()
    subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "install", "-q", *spec["pip"]], check=True)
    install_s = time.perf_counter() - started
    added = [p for p in freeze(venv) if p not in base_pkgs]
    info = {
        "pip_install": spec["pip"],
        "added_mb": round((tree_size_bytes(site_packages(venv)) - base_bytes) / 1e6, 1),
        "packages": added,
        "install_s": round(install_s, 1),
        "largest_added_mb": largest_dirs(site_packages(venv), skip=base_dirs),
    }
    record.write_text(json.dumps(info, indent=1))
    return info


def largest_dirs(sp: Path, skip: set[str], n: int = 6) -> dict:
    sizes = {d.name: tree_size_bytes(d) for d in sp.iterdir()
             if d.is_dir() and d.name not in skip and not d.name.endswith("-info")}
    return {k: round(v / 1e6, 1) for k, v in sorted(sizes.items(), key=lambda kv: -kv[1])[:n]}


# -- processes: CPU and RSS of a process tree, from /proc -------------------------------------------------------
CLK = os.sysconf("SC_CLK_TCK")


def tree_pids(root: int) -> list[int]:
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            with contextlib.suppress(OSError, IndexError, ValueError):
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
                children.setdefault(ppid, []).append(int(entry.name))
    pids, todo = [], [root]
    while todo:
        pid = todo.pop()
        pids.append(pid)
        todo += children.get(pid, [])
    return pids


def cpu_seconds(pids: list[int]) -> float:
    total = 0.0
    for pid in pids:
        with contextlib.suppress(OSError, IndexError):
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / CLK  # utime, stime
    return total


def machine_busy_seconds() -> float:
    """CPU seconds all processes of the machine spent busy (every core), from /proc/stat."""
    user, nice, system, _idle, _iowait, irq, softirq, steal = map(int, Path("/proc/stat").read_text().split()[1:9])
    return (user + nice + system + irq + softirq + steal) / CLK


def wait_until_quiet(limit: float, max_wait_s: float) -> float:
    """Wait (at most max_wait_s) for the 1-minute load average to drop under limit; the seconds waited."""
    started = time.perf_counter()
    while os.getloadavg()[0] > limit and time.perf_counter() - started < max_wait_s:
        time.sleep(5)
    return round(time.perf_counter() - started, 1)


def peak_rss_mb(pids: list[int]) -> float:
    total = 0
    for pid in pids:
        with contextlib.suppress(OSError):
            for line in Path(f"/proc/{pid}/status").read_text().splitlines():
                if line.startswith("VmHWM:"):
                    total += int(line.split()[1])
    return total / 1024


# -- a minimal websocket client (RFC 6455, client side) and the DevTools protocol over it -----------------------
class WebSocket:
    def __init__(self, url: str):
        host_port, path = url.removeprefix("ws://").split("/", 1)
        host, port = host_port.split(":")
        self.sock = socket.create_connection((host, int(port)), timeout=30)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((f"GET /{path} HTTP/1.1\r\nHost: {host_port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                           f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n").encode())
        head = b""
        while b"\r\n\r\n" not in head:
            head += self.sock.recv(1)
        if b" 101 " not in head.split(b"\r\n", 1)[0]:
            raise RuntimeError(f"websocket handshake failed: {head!r}")

    def _read(self, n: int) -> bytes:
        buf = bytearray()
        while len(buf) < n:
            chunk = self.sock.recv(n - len(buf))
            if not chunk:
                raise ConnectionError("websocket closed")
            buf += chunk
        return bytes(buf)

    def send(self, text: str) -> None:
        data, mask = text.encode(), os.urandom(4)
        n = len(data)
        head = bytes([0x81]) + (bytes([0x80 | n]) if n < 126 else
                                bytes([0x80 | 126]) + struct.pack(">H", n) if n < 65536 else
                                bytes([0x80 | 127]) + struct.pack(">Q", n))
        self.sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data)))

    def recv(self) -> str:
        message = b""
        while True:
            b0, b1 = self._read(2)
            n = b1 & 0x7F
            if n == 126:
                n = struct.unpack(">H", self._read(2))[0]
            elif n == 127:
                n = struct.unpack(">Q", self._read(8))[0]
            payload = self._read(n)
            opcode = b0 & 0x0F
            if opcode == 0x9:  # ping
                continue
            message += payload
            if b0 & 0x80:
                return message.decode()


class Cdp:
    """One page target of a running Chromium; call() waits for its reply, events are kept in order."""

    def __init__(self, ws_url: str):
        self.ws, self.next_id, self.events = WebSocket(ws_url), 0, []

    def call(self, method: str, timeout: float = 120, **params) -> dict:
        self.next_id += 1
        my_id = self.next_id
        self.ws.send(json.dumps({"id": my_id, "method": method, "params": params}))
        self.ws.sock.settimeout(timeout)
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == my_id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})
            if "method" in msg:
                self.on_event(msg)

    def on_event(self, msg: dict) -> None:
        if msg["method"] == "Page.screencastFrame":
            p = msg["params"]
            self.events.append(("frame", time.perf_counter(), hashlib.sha1(p["data"].encode()).hexdigest()))
            self.ws.send(json.dumps({"id": 0, "method": "Page.screencastFrameAck", "params": {"sessionId": p["sessionId"]}}))
        elif msg["method"] == "Network.requestWillBeSent":
            self.events.append(("request", time.perf_counter(), msg["params"]["request"]["url"]))
        elif msg["method"] == "Network.loadingFailed":
            self.events.append(("failed", time.perf_counter(), msg["params"].get("errorText", "")))

    def pump(self, seconds: float) -> None:
        """Handle events (screencast frames, requests) for a while."""
        end = time.perf_counter() + seconds
        while (left := end - time.perf_counter()) > 0:
            self.ws.sock.settimeout(left)
            try:
                msg = json.loads(self.ws.recv())
            except (TimeoutError, socket.timeout):
                break
            if "method" in msg:
                self.on_event(msg)

    def evaluate(self, expression: str):
        return self.call("Runtime.evaluate", expression=expression, returnByValue=True).get("result", {}).get("value")

    def screenshot(self, scale: float = 1.0) -> bytes:
        clip = {"x": 0, "y": 0, "width": VIEW[0], "height": VIEW[1], "scale": scale}
        return base64.b64decode(self.call("Page.captureScreenshot", format="png", clip=clip)["data"])


# A counter of animation frames and of frames in which the page issued WebGL draw calls.
FRAME_HOOK = r'''
(() => {
  const s = window.__bench = {raf: 0, glFrames: 0, draws: 0, drew: false};
  for (const C of [window.WebGLRenderingContext, window.WebGL2RenderingContext]) {
    if (!C) continue;
    for (const m of ["drawArrays", "drawElements", "drawArraysInstanced", "drawElementsInstanced", "drawRangeElements"]) {
      const f = C.prototype[m];
      if (f) C.prototype[m] = function (...a) { s.draws++; s.drew = true; return f.apply(this, a); };
    }
  }
  const tick = () => { s.raf++; if (s.drew) { s.glFrames++; s.drew = false; } requestAnimationFrame(tick); };
  requestAnimationFrame(tick);
})();
'''


# -- pictures: decode Chromium's PNG screenshots (8-bit RGB/RGBA, not interlaced) and find the yellow arm ---------
def png_pixels(png: bytes) -> tuple[int, int, int, bytes]:
    pos, idat, width = 8, b"", 0
    while pos < len(png):
        length, kind = struct.unpack(">I4s", png[pos:pos + 8])
        body = png[pos + 8:pos + 8 + length]
        if kind == b"IHDR":
            width, height, depth, ctype = struct.unpack(">IIBB", body[:10])
            assert depth == 8 and ctype in (2, 6), (depth, ctype)
            bpp = 4 if ctype == 6 else 3
        elif kind == b"IDAT":
            idat += body
        pos += 12 + length
    raw, stride = zlib.decompress(idat), width * bpp
    out, prev = bytearray(), bytearray(stride)
    for y in range(height):
        f, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b, c = prev[i], prev[i - bpp] if i >= bpp else 0
            if f == 1:
                line[i] = (line[i] + a) & 255
            elif f == 2:
                line[i] = (line[i] + b) & 255
            elif f == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        out += line
        prev = line
    return width, height, bpp, bytes(out)


def arm_pixels(png: bytes) -> float:
    """Share of the picture in the arm's yellow (URDF '3d_printed' 1.0 0.82 0.12, shaded)."""
    w, h, bpp, px = png_pixels(png)
    n = 0
    for i in range(0, len(px), bpp):
        r, g, b = px[i], px[i + 1], px[i + 2]
        if r > 90 and g > 0.55 * r and g < 0.98 * r and b < 0.45 * g:
            n += 1
    return n / (w * h)


# -- one candidate ---------------------------------------------------------------------------------------------
def launch_chromium(profile: Path) -> tuple[subprocess.Popen, Cdp]:
    shutil.rmtree(profile, ignore_errors=True)
    port = free_port()
    proc = subprocess.Popen([
        CHROMIUM, *(flag for flag in BROWSER_FLAGS if not flag.startswith("--window-size=")), f"--remote-debugging-port={port}",
        f"--user-data-dir={profile}", f"--window-size={VIEW[0]},{VIEW[1]}", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "about:blank",
    ], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    for _ in range(100):
        with contextlib.suppress(OSError):
            targets = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=1))
            page = next(t for t in targets if t["type"] == "page")
            return proc, Cdp(page["webSocketDebuggerUrl"])
        time.sleep(0.1)
    raise RuntimeError("chromium did not start")


def stop(proc: subprocess.Popen) -> None:
    """Stop a process we started and whatever it started (meshcat's server, chromium's helpers)."""
    pids = tree_pids(proc.pid)
    proc.terminate()
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(5)
    for pid in pids[1:]:
        with contextlib.suppress(OSError):
            os.kill(pid, 9)
    if proc.poll() is None:
        proc.kill()
        proc.wait()


def measure(name: str, scratch: Path, tmp: Path, duration: float) -> dict:
    python = scratch / name / "bin" / "python"
    script = tmp / f"{name}_server.py"
    script.write_text(SERVERS[name])
    browser, cdp = launch_chromium(scratch / f"profile-{name}")
    server = None
    result: dict = {}
    try:
        for domain in ("Page", "Network", "Runtime"):
            cdp.call(f"{domain}.enable")
        cdp.call("Emulation.setDeviceMetricsOverride", width=VIEW[0], height=VIEW[1], deviceScaleFactor=1, mobile=False)
        cdp.call("Page.addScriptToEvaluateOnNewDocument", source=FRAME_HOOK)
        result["webgl_renderer"] = cdp.evaluate(
            "(() => { const g = document.createElement('canvas').getContext('webgl2');"
            " const e = g && g.getExtension('WEBGL_debug_renderer_info');"
            " return g ? (e ? g.getParameter(e.UNMASKED_RENDERER_WEBGL) : 'webgl2') : 'no webgl2'; })()")

        env = dict(os.environ, URDF=str(URDF), PORT=str(free_port()), PORT2=str(free_port()), PYTHONUNBUFFERED="1")
        log = open(tmp / f"{name}_server.log", "w+")
        t0 = time.perf_counter()
        server = subprocess.Popen([str(python), str(script)], env=env, stdout=subprocess.PIPE, stderr=log, text=True)
        line = ""
        while not line.startswith("READY"):
            line = server.stdout.readline()
            if not line and server.poll() is not None:
                log.seek(0)
                raise RuntimeError(f"{name} server exited: {log.read()[-2000:]}")
        url = line.split()[1]
        result["url"] = url
        result["server_ready_s"] = round(time.perf_counter() - t0, 2)
        cdp.call("Page.navigate", url=url)
        share, drawn_at = 0.0, None
        while time.perf_counter() - t0 < 150:
            cdp.pump(0.3)
            share = arm_pixels(cdp.screenshot(scale=0.25))
            if share > 0.003:
                drawn_at = time.perf_counter()
                break
        result["arm_drawn"] = drawn_at is not None
        result["start_to_drawn_s"] = round(drawn_at - t0, 2) if drawn_at else None

        cdp.pump(2.0)  # settle
        pids = tree_pids(server.pid)
        cpu0, browser_cpu0, w0 = cpu_seconds(pids), cpu_seconds(tree_pids(browser.pid)), time.perf_counter()
        busy0, load0 = machine_busy_seconds(), os.getloadavg()
        # 5 s of animation frames and WebGL draws
        b0 = cdp.evaluate("JSON.stringify(window.__bench)")
        tb0, bc0 = time.perf_counter(), cpu_seconds(tree_pids(browser.pid))
        cdp.pump(5.0)
        b1 = cdp.evaluate("JSON.stringify(window.__bench)")
        span, browser_cpu_s = time.perf_counter() - tb0, cpu_seconds(tree_pids(browser.pid)) - bc0
        b0, b1 = json.loads(b0 or "{}"), json.loads(b1 or "{}")
        result["raf_per_s"] = round((b1.get("raf", 0) - b0.get("raf", 0)) / span, 1)
        result["gl_frames_per_s"] = round((b1.get("glFrames", 0) - b0.get("glFrames", 0)) / span, 1)
        # frames per CPU-second the browser got: comparable when other work on the machine takes CPU away
        result["gl_frames_per_browser_cpu_s"] = round(
            (b1.get("glFrames", 0) - b0.get("glFrames", 0)) / max(browser_cpu_s, 1e-3), 2)
        result["gl_draw_calls_per_frame"] = round((b1.get("draws", 0) - b0.get("draws", 0)) /
                                                  max(1, b1.get("glFrames", 0) - b0.get("glFrames", 0)), 1)
        # 5 s of screencast: one frame per changed picture (jpeg 640x360)
        cdp.events.clear()
        cdp.call("Page.startScreencast", format="jpeg", quality=60, maxWidth=640, maxHeight=360)
        ts0 = time.perf_counter()
        cdp.pump(5.0)
        cdp.call("Page.stopScreencast")
        span = time.perf_counter() - ts0
        frames = [e for e in cdp.events if e[0] == "frame"]
        result["screencast_frames_per_s"] = round(len(frames) / span, 1)
        result["screencast_distinct_per_s"] = round(len({h for _, _, h in frames}) / span, 1)
        # the rest of the window: keep animating with the browser connected
        cdp.pump(max(0.0, duration - (time.perf_counter() - w0) - 1.5))
        shot = cdp.screenshot()
        (scratch / f"{name}.png").write_bytes(shot)
        result["screenshot"] = str(scratch / f"{name}.png")
        result["arm_share_of_screenshot"] = round(arm_pixels(cdp.screenshot(scale=0.25)), 4)
        moved = cdp.screenshot(scale=0.25) != (time.sleep(0.5) or cdp.screenshot(scale=0.25))
        result["picture_changes_over_0_5_s"] = moved
        wall = time.perf_counter() - w0
        pids = tree_pids(server.pid)
        result["window_s"] = round(wall, 1)
        result["server_cpu_percent"] = round(100 * (cpu_seconds(pids) - cpu0) / wall, 1)
        result["server_processes"] = len(pids)
        result["server_peak_rss_mb"] = round(peak_rss_mb(pids), 1)
        result["browser_cpu_percent_all_processes"] = round(
            100 * (cpu_seconds(tree_pids(browser.pid)) - browser_cpu0) / wall, 1)

        # everything else on the machine over the window (other engineers' tests, this driver): contention
        result["machine_cpu_percent_others"] = round(
            100 * (machine_busy_seconds() - busy0) / wall - result["server_cpu_percent"]
            - result["browser_cpu_percent_all_processes"], 1)
        result["loadavg_window_start"] = [round(x, 2) for x in load0]
        result["loadavg_window_end"] = [round(x, 2) for x in os.getloadavg()]
    finally:
        if server is not None:
            stop(server)
        stop(browser)
    return result


def offline_check(name: str, scratch: Path, tmp: Path) -> dict:
    """A second, short visit that records every request the page makes (the first visit's log is mixed with
    screencast events): which hosts it tried, and whether any was not 127.0.0.1."""
    python = scratch / name / "bin" / "python"
    script = tmp / f"{name}_server.py"
    browser, cdp = launch_chromium(scratch / f"profile-{name}-offline")
    server = None
    try:
        cdp.call("Network.enable")
        cdp.call("Page.enable")
        cdp.call("Emulation.setDeviceMetricsOverride", width=VIEW[0], height=VIEW[1], deviceScaleFactor=1, mobile=False)
        env = dict(os.environ, URDF=str(URDF), PORT=str(free_port()), PORT2=str(free_port()), PYTHONUNBUFFERED="1")
        server = subprocess.Popen([str(python), str(script)], env=env, stdout=subprocess.PIPE,
                                  stderr=subprocess.DEVNULL, text=True)
        line = ""
        while not line.startswith("READY"):
            line = server.stdout.readline()
            if not line and server.poll() is not None:
                raise RuntimeError(f"{name} server exited")
        cdp.call("Page.navigate", url=line.split()[1])
        cdp.pump(12.0)
        urls = [u for kind, _, u in cdp.events if kind == "request"]
        failures = [u for kind, _, u in cdp.events if kind == "failed"]
        outside = sorted({u for u in urls if not u.split("//", 1)[-1].startswith(("127.0.0.1", "localhost"))
                          and not u.startswith(("data:", "blob:", "about:"))})
        return {"requests": len(urls), "requests_to_other_hosts": outside, "failed_requests": len(failures)}
    finally:
        if server is not None:
            stop(server)
        stop(browser)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", default=",".join(CANDIDATES))
    parser.add_argument("--duration", type=float, default=20.0, help="animated seconds with the browser connected")
    parser.add_argument("--scratch", type=Path, default=Path("/tmp/webcand"))
    parser.add_argument("--quiet-load", type=float, default=1.0,
                        help="before each candidate, wait for the 1-min load average to fall under this")
    parser.add_argument("--quiet-wait", type=float, default=60.0, help="... but no longer than this, seconds")
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "web-candidates.json")
    args = parser.parse_args()
    if not URDF.exists():
        sys.exit(f"{URDF} is missing: run `.venv/bin/so101 assets` first")
    if not shutil.which(CHROMIUM):
        sys.exit("chromium is missing: apt-get update && apt-get install -y chromium")
    args.scratch.mkdir(parents=True, exist_ok=True)
    names = [n for n in args.only.split(",") if n]
    results = {"machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                           "chromium": subprocess.run([CHROMIUM, "--version"], capture_output=True, text=True).stdout.strip(),
                           "loadavg_start": os.getloadavg(), "when": time.strftime("%Y-%m-%d %H:%M:%S")},
               "candidates": {}}
    with tempfile.TemporaryDirectory(prefix="webcand-") as tmp_name:
        tmp = Path(tmp_name)
        for name in names:
            print(f"== {name}", flush=True)
            entry = {"install": ensure_venv(args.scratch, name), "features": FEATURES[name]}
            entry["waited_for_quiet_s"] = wait_until_quiet(args.quiet_load, args.quiet_wait)
            try:
                entry["run"] = measure(name, args.scratch, tmp, args.duration)
                entry["offline"] = offline_check(name, args.scratch, tmp)
                entry["offline"]["verdict"] = ("yes" if entry["run"]["arm_drawn"] and not entry["offline"]["requests_to_other_hosts"]
                                               else "draws, but tries other hosts" if entry["run"]["arm_drawn"] else "no")
            except Exception as exc:  # a candidate that fails is reported, the others still run
                entry["error"] = f"{type(exc).__name__}: {exc}"
            results["candidates"][name] = entry
            print(json.dumps(entry.get("run", entry.get("error")), indent=1), flush=True)
    results["machine"]["loadavg_end"] = os.getloadavg()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1) + "\n")
    print_table(results)
    print(f"\nwrote {args.out}")


def print_table(results: dict) -> None:
    rows = [
        ("install added, MB", lambda e: e["install"]["added_mb"]),
        ("packages added", lambda e: len(e["install"]["packages"])),
        ("arm drawn", lambda e: e["run"]["arm_drawn"]),
        ("offline (other hosts tried)", lambda e: f'{e["offline"]["verdict"]} ({len(e["offline"]["requests_to_other_hosts"])})'),
        ("server start -> ready, s", lambda e: e["run"]["server_ready_s"]),
        ("server start -> arm drawn, s", lambda e: e["run"]["start_to_drawn_s"]),
        ("server CPU %", lambda e: e["run"]["server_cpu_percent"]),
        ("server peak RSS, MB", lambda e: e["run"]["server_peak_rss_mb"]),
        ("browser CPU % (all procs)", lambda e: e["run"]["browser_cpu_percent_all_processes"]),
        ("other CPU % on the machine", lambda e: e["run"]["machine_cpu_percent_others"]),
        ("load avg 1-min, window end", lambda e: e["run"]["loadavg_window_end"][0]),
        ("rAF/s", lambda e: e["run"]["raf_per_s"]),
        ("frames with WebGL draws/s", lambda e: e["run"]["gl_frames_per_s"]),
        ("  per browser CPU-second", lambda e: e["run"]["gl_frames_per_browser_cpu_s"]),
        ("screencast frames/s", lambda e: e["run"]["screencast_frames_per_s"]),
        ("  distinct pictures/s", lambda e: e["run"]["screencast_distinct_per_s"]),
        ("picture changes in 0.5 s", lambda e: e["run"]["picture_changes_over_0_5_s"]),
    ]
    names = list(results["candidates"])
    print("\n" + f"{'':30}" + "".join(f"{n:>22}" for n in names))
    for label, get in rows:
        cells = []
        for n in names:
            try:
                cells.append(str(get(results["candidates"][n])))
            except (KeyError, TypeError):
                cells.append("-")
        print(f"{label:30}" + "".join(f"{c:>22}" for c in cells))
    m = results["machine"]
    print(f"\nload average at start {tuple(round(x, 2) for x in m['loadavg_start'])}, "
          f"at end {tuple(round(x, 2) for x in m['loadavg_end'])}; {m['cpus']} CPUs; {m['chromium']}")


if __name__ == "__main__":
    main()
