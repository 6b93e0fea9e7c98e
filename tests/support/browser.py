"""Headless Chromium driven over the Chrome DevTools protocol, to look at a page as a person would.

No driver package: Chromium speaks the protocol over a pipe (`--remote-debugging-pipe`: commands on
fd 3, answers and events on fd 4, each a JSON message ended by a NUL byte), so the tests need only
Debian's `chromium` (installed by the README's install command). The browser starts with a new empty
profile and with every background service off (updates, sync, safe browsing, QUIC): on a closed
network its own connections are refused, and a report must not make any.

    with Browser() as b:
        page = b.open(Path("report.html").resolve().as_uri())
        page.evaluate("document.title"); page.screenshot(); page.requests; page.errors
"""

from __future__ import annotations

import base64
import contextlib
import fcntl
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-default-apps",
    "--disable-extensions",
    "--hide-scrollbars",
    "--mute-audio",
    "--remote-debugging-pipe",
)


def chromium_path() -> str | None:
    for name in ("chromium", "chromium-browser"):
        found = shutil.which(name)
        if found:
            return found
    return None


class BrowserError(RuntimeError):
    pass


def _above_nine(fd: int) -> int:
    high = fcntl.fcntl(fd, fcntl.F_DUPFD, 10)
    os.close(fd)
    return high


@dataclass
class Page:
    browser: Browser
    session: str
    requests: list[str] = field(default_factory=list)  # every URL the page asked for
    blocked: list[str] = field(default_factory=list)  # of those, refused by the browser before sending
    _ids: dict[str, str] = field(default_factory=dict)
    errors: list[str] = field(default_factory=list)  # console errors, exceptions, failed loads

    def call(self, method: str, **params: Any) -> dict[str, Any]:
        return self.browser.call(method, params, self.session)

    def evaluate(self, expression: str) -> Any:
        out = self.call("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        if "exceptionDetails" in out:
            raise BrowserError(f"{expression[:60]!r}: {out['exceptionDetails']}")
        return out["result"].get("value")

    def screenshot(self, path: Path, width: int = 1100, height: int | None = None) -> bytes:
        """A PNG of the page at `width` CSS pixels: its top `height` pixels, or the whole page."""
        metrics = self.call("Page.getLayoutMetrics")
        full = int(metrics["cssContentSize"]["height"])
        h = min(full, height) if height else full
        shot = self.call(
            "Page.captureScreenshot",
            format="png",
            captureBeyondViewport=True,
            clip={"x": 0, "y": 0, "width": width, "height": h, "scale": 1},
        )
        data = base64.b64decode(shot["data"])
        Path(path).write_bytes(data)
        return data


class Browser:
    def __init__(self, timeout_s: float = 60.0, width: int = 1100, height: int = 1400) -> None:
        exe = chromium_path()
        if exe is None:
            raise BrowserError("chromium not found (apt-get install -y chromium)")
        self.timeout_s = timeout_s
        self.size = (width, height)
        self._profile = tempfile.TemporaryDirectory(prefix="spooflens-chromium-")
        cmd_r, self._cmd_w = os.pipe()
        self._out_r, out_w = os.pipe()
        # the child's ends above 9, so moving them onto 3 and 4 cannot clobber one with the other
        cmd_r, out_w = (_above_nine(fd) for fd in (cmd_r, out_w))

        args = [*CHROMIUM_FLAGS, f"--user-data-dir={self._profile.name}", f"--window-size={width},{height}"]
        # the protocol's descriptors are 3 and 4 in the browser: a tiny exec shim moves our pipe ends there
        # (sh cannot name descriptors above 9; preexec_fn runs before subprocess closes unlisted ones)
        shim = "import os, sys; os.dup2(int(sys.argv[1]), 3); os.dup2(int(sys.argv[2]), 4); " + (
            "os.execv(sys.argv[3], sys.argv[3:])"
        )
        self.proc = subprocess.Popen(
            [sys.executable, "-c", shim, str(cmd_r), str(out_w), exe, *args],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            pass_fds=(cmd_r, out_w),
        )
        os.close(cmd_r)
        os.close(out_w)
        self._buffer = b""
        self._next_id = 0
        self._events: list[dict[str, Any]] = []

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        try:
            if self.proc.poll() is None:
                self._send({"id": 10**9, "method": "Browser.close"})
                self.proc.wait(timeout=10)
        except (OSError, subprocess.TimeoutExpired):
            self.proc.kill()
            self.proc.wait()
        finally:
            for fd in (self._cmd_w, self._out_r):
                with contextlib.suppress(OSError):
                    os.close(fd)
            self._profile.cleanup()

    def _send(self, message: dict[str, Any]) -> None:
        os.write(self._cmd_w, json.dumps(message).encode() + b"\0")

    def _receive(self, deadline: float) -> dict[str, Any]:
        while b"\0" not in self._buffer:
            if time.monotonic() > deadline:
                raise BrowserError("chromium did not answer in time")
            chunk = os.read(self._out_r, 1 << 20)
            if not chunk:
                raise BrowserError(f"chromium exited (code {self.proc.poll()})")
            self._buffer += chunk
        raw, _, self._buffer = self._buffer.partition(b"\0")
        message: dict[str, Any] = json.loads(raw)
        return message

    def call(self, method: str, params: dict[str, Any] | None = None, session: str | None = None) -> dict[str, Any]:
        self._next_id += 1
        message: dict[str, Any] = {"id": self._next_id, "method": method, "params": params or {}}
        if session:
            message["sessionId"] = session
        self._send(message)
        deadline = time.monotonic() + self.timeout_s
        while True:
            answer = self._receive(deadline)
            if answer.get("id") == self._next_id:
                if "error" in answer:
                    raise BrowserError(f"{method}: {answer['error']}")
                result: dict[str, Any] = answer.get("result", {})
                return result
            if "method" in answer:
                self._events.append(answer)

    def _drain(self, page: Page) -> None:
        for e in self._events:
            if e.get("sessionId") != page.session:
                continue
            p = e.get("params", {})
            match e["method"]:
                case "Network.requestWillBeSent":
                    page.requests.append(p["request"]["url"])
                    page._ids[p["requestId"]] = p["request"]["url"]
                case "Network.loadingFailed" if p.get("blockedReason"):
                    page.blocked.append(page._ids.get(p["requestId"], "?"))
                case "Network.loadingFailed":
                    page.errors.append(f"load failed: {page._ids.get(p['requestId'], '?')}: {p.get('errorText')}")
                case "Runtime.exceptionThrown":
                    page.errors.append(f"exception: {p['exceptionDetails'].get('text')}")
                case "Runtime.consoleAPICalled" if p.get("type") in ("error", "assert"):
                    page.errors.append(f"console.{p['type']}: {[a.get('value') for a in p.get('args', [])]}")
                case "Log.entryAdded" if p["entry"].get("level") == "error":
                    page.errors.append(f"log: {p['entry'].get('text')}")
        self._events = [e for e in self._events if e.get("sessionId") != page.session]

    def open(self, url: str, settle_s: float = 0.3) -> Page:
        """Load `url` in a new tab and wait for its load event; the page records requests and errors."""
        target = self.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        session = self.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        page = Page(self, session)
        for domain in ("Page", "Runtime", "Network", "Log"):
            page.call(f"{domain}.enable")
        w, h = self.size
        page.call("Emulation.setDeviceMetricsOverride", width=w, height=h, deviceScaleFactor=1, mobile=False)
        page.call("Page.navigate", url=url)
        deadline = time.monotonic() + self.timeout_s
        while not any(e.get("method") == "Page.loadEventFired" and e.get("sessionId") == session for e in self._events):
            self._events.append(self._receive(deadline))
        time.sleep(settle_s)
        page.evaluate("1")  # collects the events that arrived meanwhile
        self._drain(page)
        return page

    def collect(self, page: Page) -> None:
        """Fold events received since the last call into the page's requests and errors."""
        page.evaluate("1")
        self._drain(page)

    def wait_for(self, page: Page, done: Callable[[Page], bool], timeout_s: float, then_s: float = 0.0) -> None:
        """Collect the page's events until `done(page)` holds (or `timeout_s`), then for `then_s` more."""
        deadline = time.monotonic() + timeout_s
        while not done(page) and time.monotonic() < deadline:
            time.sleep(0.2)
            self.collect(page)
        time.sleep(then_s)
        self.collect(page)
