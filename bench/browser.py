"""A headless Chromium for the tests and `so101 bench`, driven over its DevTools protocol: WebGL
through SwiftShader (no GPU), and every host but 127.0.0.1 unreachable, so a page that needs the
internet fails here."""

from __future__ import annotations

import asyncio
import base64
import itertools
import json
import os
import shutil
import signal
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path

from so101.runtime.processes import stop_process

CHROMIUM = shutil.which("chromium")
CALL_TIMEOUT_S = 60.0
FLAGS = ("--headless=new", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
         "--window-size=1200,800", "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
         # A headless page counts as hidden: without these its animation frames are throttled.
         "--disable-renderer-backgrounding", "--disable-background-timer-throttling",
         "--disable-backgrounding-occluded-windows")


class Browser:
    """One Chromium with one page; `kill()` ends it (as a person closing it would). `idle`: its processes
    run under SCHED_IDLE, taking only the CPU nothing else wants (Chromium raises its own processes'
    nice value, so nice 19 is not enough)."""

    def __init__(self, debug_port: int, idle: bool = False):
        self._profile = tempfile.TemporaryDirectory(prefix="so101-chromium-", ignore_cleanup_errors=True)
        self.process = subprocess.Popen(
            [str(CHROMIUM), *FLAGS, f"--remote-debugging-port={debug_port}", f"--user-data-dir={self._profile.name}",
             "about:blank"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            start_new_session=True,  # its own process group: kill() ends every helper process with it
            preexec_fn=(lambda: os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))) if idle else None)
        deadline = time.monotonic() + 30
        while True:
            try:
                pages = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{debug_port}/json", timeout=1).read())
                self._socket_url = next(page["webSocketDebuggerUrl"] for page in pages if page["type"] == "page")
                break
            except (OSError, StopIteration, ValueError):
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)
        self._ids = itertools.count(1)

    def _call(self, method: str, **params) -> dict:
        """One DevTools call; TimeoutError after CALL_TIMEOUT_S (a page busy drawing in software can stall)."""
        import websockets  # viser's dependency; imported here so bench/web_candidates.py can read FLAGS without it

        async def call() -> dict:
            async with websockets.connect(self._socket_url, max_size=2**27) as socket:
                request = next(self._ids)
                await socket.send(json.dumps({"id": request, "method": method, "params": params}))
                while True:
                    message = json.loads(await socket.recv())
                    if message.get("id") == request:
                        return message.get("result", {})
        return asyncio.run(asyncio.wait_for(call(), CALL_TIMEOUT_S))

    def open(self, url: str) -> None:
        # A page of a headless browser counts as hidden and unfocused: some pages then stop animating.
        self._call("Emulation.setFocusEmulationEnabled", enabled=True)
        self._call("Page.bringToFront")
        self._call("Page.navigate", url=url)

    def evaluate(self, expression: str):
        """The value of a JavaScript expression in the page (None if it has none)."""
        return self._call("Runtime.evaluate", expression=expression, returnByValue=True).get("result", {}).get("value")

    def text(self) -> str:
        return str(self.evaluate("document.body ? document.body.innerText : ''") or "")

    def wait_for_text(self, needle: str, timeout_s: float = 60) -> str:
        deadline = time.monotonic() + timeout_s
        while needle not in (text := self.text()):
            if time.monotonic() > deadline:
                raise AssertionError(f"{needle!r} not on the page within {timeout_s} s: {text[:500]!r}")
            time.sleep(0.3)
        return text

    def screenshot(self, path: Path) -> Path:
        path.write_bytes(base64.b64decode(self._call("Page.captureScreenshot", format="png")["data"]))
        return path

    def kill(self) -> None:
        stop_process(self.process, 5, ask_session=True, kill_session=True, first_signal=signal.SIGKILL)
        self._profile.cleanup()
