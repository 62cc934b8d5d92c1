"""Headless Chromium driven over the Chrome DevTools Protocol, for the report's browser test.

Debian's `chromium` is started with `--remote-debugging-port=0`; its page target is driven over
a websocket (tornado's client, which the test extra's `distributed` brings). Only what the test
needs: open a URL, evaluate JavaScript, collect console errors and exceptions, take screenshots.
"""

from __future__ import annotations

import asyncio
import base64
import itertools
import json
import re
import shutil
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path

CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def find_chromium() -> str | None:
    """The first Chromium binary on PATH, or None."""
    return next((p for p in map(shutil.which, CANDIDATES) if p), None)


class Chromium:
    """One headless Chromium with one page. Use as a context manager."""

    def __init__(self, binary: str, *, width: int = 1400, height: int = 1000, timeout_s: float = 120.0):
        from tornado.websocket import websocket_connect

        self.timeout_s = timeout_s
        self._profile = tempfile.TemporaryDirectory(prefix="chromium-", ignore_cleanup_errors=True)
        self._proc = subprocess.Popen(
            [binary, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--no-default-browser-check",
             "--disable-extensions", "--remote-debugging-port=0", f"--user-data-dir={self._profile.name}",
             f"--window-size={width},{height}", "about:blank"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        self._ws = None
        self._loop = asyncio.new_event_loop()
        self._ids = itertools.count(1)
        self.events: list[dict] = []
        try:
            port = self._devtools_port()
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=timeout_s) as resp:
                targets = json.load(resp)
            url = next(t["webSocketDebuggerUrl"] for t in targets if t["type"] == "page")

            async def connect():
                return await websocket_connect(url, max_message_size=256 * 2**20)

            self._ws = self._loop.run_until_complete(connect())
            for domain in ("Page", "Runtime", "Log"):
                self.send(f"{domain}.enable")
        except BaseException:
            self.close()
            raise

    def _devtools_port(self) -> int:
        deadline = time.monotonic() + self.timeout_s
        seen = []
        while time.monotonic() < deadline:
            line = self._proc.stderr.readline()
            if not line and self._proc.poll() is not None:
                break
            seen.append(line)
            m = re.search(r"DevTools listening on ws://[^:]+:(\d+)/", line)
            if m:
                return int(m.group(1))
        raise RuntimeError("chromium did not start: " + "".join(seen[-5:]))

    async def _call(self, method: str, params: dict) -> dict:
        msg_id = next(self._ids)
        await self._ws.write_message(json.dumps({"id": msg_id, "method": method, "params": params}))
        while True:
            raw = await asyncio.wait_for(self._ws.read_message(), self.timeout_s)
            if raw is None:
                raise RuntimeError("the DevTools connection closed")
            msg = json.loads(raw)
            if msg.get("id") == msg_id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})
            if "method" in msg:
                self.events.append(msg)

    def send(self, method: str, **params) -> dict:
        """Call one DevTools method; events that arrive meanwhile are kept in `events`."""
        return self._loop.run_until_complete(self._call(method, params))

    def wait_for_event(self, method: str) -> dict:
        """Wait until an event of `method` has arrived (kept in `events`) and return it."""

        async def wait():
            while True:
                found = next((e for e in self.events if e["method"] == method), None)
                if found:
                    return found
                raw = await asyncio.wait_for(self._ws.read_message(), self.timeout_s)
                if raw is None:
                    raise RuntimeError("the DevTools connection closed")
                msg = json.loads(raw)
                if "method" in msg:
                    self.events.append(msg)

        return self._loop.run_until_complete(wait())

    def open(self, url: str) -> None:
        """Navigate and wait for the load event."""
        self.events = [e for e in self.events if e["method"] != "Page.loadEventFired"]
        self.send("Page.navigate", url=url)
        self.wait_for_event("Page.loadEventFired")

    def evaluate(self, expression: str):
        """The value of a JavaScript expression in the page (exceptions raise)."""
        res = self.send("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        if "exceptionDetails" in res:
            raise RuntimeError(f"JavaScript error: {res['exceptionDetails']}")
        return res["result"].get("value")

    def errors(self) -> list[str]:
        """Console errors, uncaught exceptions and error log entries seen so far."""
        out = []
        for e in self.events:
            p = e.get("params", {})
            if e["method"] == "Runtime.exceptionThrown":
                d = p["exceptionDetails"]
                out.append(f"exception: {d.get('exception', {}).get('description') or d.get('text')}")
            elif e["method"] == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
                out.append("console.error: " + " ".join(str(a.get("value", a.get("description"))) for a in p["args"]))
            elif e["method"] == "Log.entryAdded" and p["entry"]["level"] == "error":
                out.append(f"log: {p['entry']['text']}")
        return out

    def screenshot(self, path: Path, *, selector: str | None = None, full_width: int = 1400) -> Path:
        """A PNG of the viewport, or of the element `selector` (scrolled into view)."""
        params: dict = {"format": "png"}
        if selector:
            r = self.evaluate(f"(() => {{ const e = document.querySelector({json.dumps(selector)}); "
                              "e.scrollIntoView(); const b = e.getBoundingClientRect(); "
                              "return [b.left + scrollX, b.top + scrollY, b.width, b.height]; })()")
            params.update(clip={"x": r[0], "y": r[1], "width": r[2], "height": r[3], "scale": 1},
                          captureBeyondViewport=True)
        data = self.send("Page.captureScreenshot", **params)["data"]
        Path(path).write_bytes(base64.b64decode(data))
        return Path(path)

    def close(self) -> None:
        if self._ws is not None:
            self._ws.close()
            self._ws = None
        if not self._loop.is_closed():
            self._loop.close()
        if self._proc.poll() is None:
            self._proc.terminate()
            try:
                self._proc.wait(10)
            except subprocess.TimeoutExpired:
                self._proc.kill()
        self._profile.cleanup()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
