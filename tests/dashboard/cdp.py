"""Headless Chromium driven over the Chrome DevTools Protocol, with nothing but ``websockets``.

``Chromium.launch`` starts Debian's chromium with ``--remote-debugging-port=0`` and connects to the
browser endpoint it announces in ``DevToolsActivePort``; ``new_page`` opens a tab and attaches a
flat session to it. Every wait has a deadline, so a broken page fails a test instead of hanging it.
"""

from __future__ import annotations

import base64
import itertools
import json
import os
import re
import shutil
import signal
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from websockets.sync.client import ClientConnection, connect

CHROMIUM_FLAGS = (
    "--headless=new",
    "--no-sandbox",  # root, in a container
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-extensions",
    "--mute-audio",
    "--hide-scrollbars",
    "--no-proxy-server",  # loopback only; ignore any proxy in the environment
    "--remote-debugging-port=0",
)


class CdpError(RuntimeError):
    """A protocol command failed, or the page did something a test did not expect."""


def find_chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


class Chromium:
    """One browser process and its DevTools connection."""

    def __init__(self, process: subprocess.Popen[bytes], socket: ClientConnection) -> None:
        self.process = process
        self.socket = socket
        self.ids = itertools.count(1)
        self.events: list[dict[str, Any]] = []

    @classmethod
    def launch(cls, executable: str, profile: Path, width: int = 1600, height: int = 1000, timeout_s: float = 20.0) -> Chromium:
        profile.mkdir(parents=True, exist_ok=True)
        log = open(profile / "chromium.log", "wb")  # chromium is chatty on stderr (dbus, gcm): keep it out of pipes
        process = subprocess.Popen(
            [executable, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", f"--window-size={width},{height}", "about:blank"],
            stdout=log,
            stderr=log,
            start_new_session=True,  # its own process group, so teardown can end all its children
        )
        log.close()
        port_file = profile / "DevToolsActivePort"
        deadline = time.monotonic() + timeout_s
        while True:
            lines = port_file.read_text().split("\n") if port_file.exists() else []
            if len(lines) >= 2 and lines[0].strip() and lines[1].strip():
                break
            if process.poll() is not None or time.monotonic() > deadline:
                _end(process)
                raise CdpError(f"chromium did not start; see {profile / 'chromium.log'}")
            time.sleep(0.05)
        url = f"ws://127.0.0.1:{lines[0].strip()}{lines[1].strip()}"
        socket = connect(url, max_size=64 * 2**20, open_timeout=timeout_s, proxy=None)
        return cls(process, socket)

    def call(self, method: str, params: dict[str, Any] | None = None, session: str | None = None, timeout_s: float = 10.0) -> dict[str, Any]:
        """Send one command and return its result; events that arrive meanwhile are kept."""
        message_id = next(self.ids)
        message: dict[str, Any] = {"id": message_id, "method": method, "params": params or {}}
        if session is not None:
            message["sessionId"] = session
        self.socket.send(json.dumps(message))
        deadline = time.monotonic() + timeout_s
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise CdpError(f"{method}: no answer in {timeout_s} s")
            reply = json.loads(self.socket.recv(timeout=remaining))
            if reply.get("id") == message_id:
                if "error" in reply:
                    raise CdpError(f"{method}: {reply['error'].get('message')}")
                return reply.get("result", {})
            if "method" in reply:
                self.events.append(reply)

    def new_page(self, width: int = 1600, height: int = 1000) -> Page:
        target = self.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        session = self.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        page = Page(self, target, session)
        for domain in ("Page", "Runtime", "Log"):
            page.call(f"{domain}.enable")
        page.call("Page.bringToFront")  # a background tab gets no animation frames, so no screenshots
        page.call("Emulation.setDeviceMetricsOverride", {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False})
        return page

    def close(self) -> None:
        try:
            self.socket.close()
        finally:
            _end(self.process)


def _end(process: subprocess.Popen[bytes]) -> None:
    if process.poll() is None:
        try:
            os.killpg(process.pid, signal.SIGTERM)
            process.wait(timeout=5)
        except (ProcessLookupError, subprocess.TimeoutExpired):
            try:
                os.killpg(process.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            process.wait(timeout=5)


class Page:
    """One tab: navigate, evaluate JavaScript, wait, click, type, take screenshots."""

    def __init__(self, browser: Chromium, target: str, session: str) -> None:
        self.browser = browser
        self.target = target
        self.session = session

    def call(self, method: str, params: dict[str, Any] | None = None, timeout_s: float = 10.0) -> dict[str, Any]:
        return self.browser.call(method, params, session=self.session, timeout_s=timeout_s)

    def goto(self, url: str) -> None:
        self.call("Page.navigate", {"url": url})

    def reload(self) -> None:
        self.call("Page.reload", {"ignoreCache": True})

    def evaluate(self, expression: str) -> Any:
        """The JSON value of ``expression`` (awaited if it is a promise); CdpError if it throws."""
        result = self.call(
            "Runtime.evaluate",
            {"expression": expression, "returnByValue": True, "awaitPromise": True, "timeout": 5000},
        )
        if "exceptionDetails" in result:
            details = result["exceptionDetails"]
            text = details.get("exception", {}).get("description") or details.get("text")
            raise CdpError(f"{expression!r} threw: {text}")
        return result["result"].get("value")

    def wait_for(self, expression: str, timeout_s: float = 10.0, what: str | None = None) -> Any:
        """Poll ``expression`` until it is truthy in JavaScript; return its value (``True`` for a DOM
        node). CdpError after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        truthy = f"(() => {{ const v = ({expression}); return v ? (v instanceof Node ? true : v) : null; }})()"
        while True:
            try:
                value = self.evaluate(truthy)
            except CdpError:
                value = None  # e.g. the page is still loading its modules
            if value:
                return value
            if time.monotonic() > deadline:
                raise CdpError(f"waited {timeout_s} s for {what or expression}")
            time.sleep(0.05)

    def move_to(self, x: float, y: float) -> None:
        """Move the mouse pointer to page pixel (x, y), as a user hovering there."""
        self.call("Input.dispatchMouseEvent", {"type": "mouseMoved", "x": x, "y": y})

    def centre_of(self, selector: str) -> dict[str, float]:
        """The page pixel at the middle of the first visible element matching ``selector``."""
        return self.wait_for(
            f"""(() => {{
                const node = document.querySelector({json.dumps(selector)});
                if (!node || node.hidden) return null;
                const r = node.getBoundingClientRect();
                return r.width && r.height ? {{x: r.left + r.width / 2, y: r.top + r.height / 2}} : null;
            }})()""",
            what=f"a visible {selector}",
        )

    def click_at(self, x: float, y: float) -> None:
        """A real left click (pointer moved, pressed, released) at page pixel (x, y)."""
        self.call("Input.dispatchMouseEvent", {"type": "mouseMoved", "x": x, "y": y})
        for kind in ("mousePressed", "mouseReleased"):
            self.call("Input.dispatchMouseEvent", {"type": kind, "x": x, "y": y, "button": "left", "clickCount": 1})

    def click(self, selector: str) -> None:
        """Click the middle of the first element matching ``selector`` (scrolled into view)."""
        box = self.wait_for(
            f"""(() => {{
                const node = document.querySelector({json.dumps(selector)});
                if (!node || node.hidden) return null;
                node.scrollIntoView({{block: "center"}});
                const r = node.getBoundingClientRect();
                return r.width && r.height ? {{x: r.left + r.width / 2, y: r.top + r.height / 2}} : null;
            }})()""",
            what=f"a visible {selector}",
        )
        self.click_at(box["x"], box["y"])

    def click_until(self, selector: str, expression: str, what: str, timeout_s: float = 10.0) -> None:
        """Click ``selector`` until ``expression`` holds, as a user clicks again when a click did
        nothing: a live page redrawn between the press and the release (a rebuilt row, a shifted
        layout) takes no click. CdpError after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while True:
            self.click(selector)
            try:
                self.wait_for(expression, timeout_s=min(1.0, max(deadline - time.monotonic(), 0.05)), what=what)
                return
            except CdpError:
                if time.monotonic() > deadline:
                    raise CdpError(f"clicked {selector} for {timeout_s} s without {what}") from None

    def press(self, key: str, code: str | None = None, text: str | None = None) -> None:
        """Press and release one key on whatever has the focus (``press("Enter", text="\\r")``)."""
        base = {"key": key, "code": code or key}
        down = {**base, "type": "keyDown" if text else "rawKeyDown", **({"text": text} if text else {})}
        self.call("Input.dispatchKeyEvent", down)
        self.call("Input.dispatchKeyEvent", {**base, "type": "keyUp"})

    def screenshot(self) -> bytes:
        return base64.b64decode(self.call("Page.captureScreenshot", {"format": "png"}, timeout_s=20.0)["data"])

    def errors(self) -> list[str]:
        """Console errors, uncaught exceptions and failed loads this page has reported so far. The
        503 of ``/api/health`` while the site is not ok is an answer the dashboard reads (its body
        says why), not a failure, so Chromium's "failed to load" line for it is left out."""
        return [e for e in self._all_errors() if not EXPECTED_HEALTH_503.search(e)]

    def _all_errors(self) -> list[str]:
        self.evaluate("0")  # a round trip, so events sent before it have been read
        found = []
        for event in self.browser.events:
            if event.get("sessionId") != self.session:
                continue
            params = event.get("params", {})
            if event["method"] == "Runtime.exceptionThrown":
                details = params["exceptionDetails"]
                found.append(details.get("exception", {}).get("description") or details.get("text", "exception"))
            elif event["method"] == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
                found.append(" ".join(str(a.get("value", a.get("description", ""))) for a in params.get("args", [])))
            elif event["method"] == "Log.entryAdded" and params["entry"].get("level") == "error":
                entry = params["entry"]
                found.append(f"{entry.get('text')} ({entry.get('url', '')})")
        return found

    def close(self) -> None:
        self.browser.call("Target.closeTarget", {"targetId": self.target})


EXPECTED_HEALTH_503 = re.compile(r"^Failed to load resource: the server responded with a status of 503 .*/api/health\)$")


def wait_until(condition: Callable[[], Any], timeout_s: float, what: str) -> Any:
    """Poll a Python-side ``condition`` until truthy; CdpError after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while not (value := condition()):
        if time.monotonic() > deadline:
            raise CdpError(f"waited {timeout_s} s for {what}")
        time.sleep(0.05)
    return value
