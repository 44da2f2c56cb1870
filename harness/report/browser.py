"""A headless Chromium driven over the DevTools protocol on a pipe, for looking at a report as a
reader does: the report's browser test and `scripts/screenshots` use it.

`--remote-debugging-pipe`: fd 3 carries commands in, fd 4 replies and events out, each message
JSON ending in a NUL byte. `DevTools.open(url)` loads a page in a window of the given size (the
page's Content-Security-Policy bypassed, so a reference to anything outside the file shows up as
a request instead of being blocked silently; `--host-resolver-rules` maps every host name to
nothing as a second guard); `evaluate` reads the DOM, `screenshot` writes a PNG, `requests`
lists the page's network requests. Debian's `chromium` package provides the browser.
"""

from __future__ import annotations

import base64
import fcntl
import json
import os
import select
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

__all__ = ["DevTools", "chromium_binary", "TIMEOUT_S"]

# Seconds to wait for any answer of the browser.
TIMEOUT_S = 60.0


def chromium_binary() -> str | None:
    """The path of the Chromium executable on PATH.

    Returns
    -------
    str or None: the path of `chromium` or `chromium-browser`; None when neither is installed.
    """
    return shutil.which("chromium") or shutil.which("chromium-browser")


class DevTools:
    """A headless chromium driven over --remote-debugging-pipe."""

    def __init__(self, binary: str, profile: Path):
        to_child_r, self._w = os.pipe()
        self._r, from_child_w = os.pipe()
        # move the child's ends above 4, so that putting them on 3 and 4 cannot overwrite one
        # with the other
        to_child_r, from_child_w = _above_four(to_child_r), _above_four(from_child_w)
        args = [
            "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
            "--disable-background-networking", "--disable-component-update", "--disable-sync",
            "--disable-dev-shm-usage", "--disable-extensions", "--mute-audio",
            "--host-resolver-rules=MAP * ~NOTFOUND", f"--user-data-dir={profile}",
            "--remote-debugging-pipe", "about:blank",
        ]
        # a tiny Python trampoline puts the pipe ends on fds 3 and 4, where chromium expects them
        self.proc = subprocess.Popen(
            [sys.executable, "-S", "-c", _TRAMPOLINE, str(to_child_r), str(from_child_w), binary,
             *args],
            pass_fds=(to_child_r, from_child_w), stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )
        os.close(to_child_r)
        os.close(from_child_w)
        self._buf = b""
        self._id = 0
        self.events: list[dict] = []
        self.session: str | None = None

    def _read_message(self, deadline: float) -> dict:
        while b"\0" not in self._buf:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError("chromium did not answer in time")
            ready, _, _ = select.select([self._r], [], [], left)
            if ready:
                chunk = os.read(self._r, 1 << 20)
                if not chunk:
                    raise RuntimeError(f"chromium closed the pipe (exit {self.proc.poll()})")
                self._buf += chunk
        raw, self._buf = self._buf.split(b"\0", 1)
        return json.loads(raw)

    def send(self, method: str, params: dict | None = None, *, session: bool = True) -> dict:
        """Send one DevTools command and wait for its reply (events read meanwhile are kept).

        Parameters
        ----------
        method : str, the protocol method ('Page.navigate', ...).
        params : dict, optional, its parameters.
        session : bool, optional, address the attached page rather than the browser (default True).

        Returns
        -------
        dict: the reply's result; RuntimeError when the browser answers with an error or closes
            the pipe, TimeoutError when no reply comes within TIMEOUT_S seconds.
        """
        self._id += 1
        msg: dict[str, Any] = {"id": self._id, "method": method, "params": params or {}}
        if session and self.session:
            msg["sessionId"] = self.session
        os.write(self._w, json.dumps(msg).encode() + b"\0")
        deadline = time.monotonic() + TIMEOUT_S
        while True:
            reply = self._read_message(deadline)
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})
            self.events.append(reply)

    def wait_for(self, method: str) -> dict:
        """Wait for an event, taking it from those already read when it came before.

        Parameters
        ----------
        method : str, the event's name ('Page.loadEventFired', ...).

        Returns
        -------
        dict: the event message; TimeoutError after TIMEOUT_S seconds without it.
        """
        for i, ev in enumerate(self.events):
            if ev.get("method") == method:
                return self.events.pop(i)
        deadline = time.monotonic() + TIMEOUT_S
        while True:
            ev = self._read_message(deadline)
            if ev.get("method") == method:
                return ev
            self.events.append(ev)

    def open(self, url: str, width: int = 1280, height: int = 1800) -> None:
        """Open `url` in a new page of the given window size and wait until it has loaded.

        Parameters
        ----------
        url : str, the page (a file:// URL for a report).
        width, height : int, optional, the window in CSS pixels (default 1280 x 1800).
        """
        target = self.send("Target.createTarget", {"url": "about:blank"}, session=False)
        attached = self.send("Target.attachToTarget",
                             {"targetId": target["targetId"], "flatten": True}, session=False)
        self.session = attached["sessionId"]
        self.send("Page.enable")
        self.send("Network.enable")
        self.send("Page.setBypassCSP", {"enabled": True})
        self.send("Emulation.setDeviceMetricsOverride",
                  {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False})
        self.events.clear()
        self.send("Page.navigate", {"url": url})
        self.wait_for("Page.loadEventFired")

    def evaluate(self, expression: str) -> Any:
        """Evaluate a JavaScript expression in the open page.

        Parameters
        ----------
        expression : str, JavaScript (its value must be JSON-serialisable).

        Returns
        -------
        Any: its value, as JSON gives it back; RuntimeError when the expression throws.
        """
        result = self.send("Runtime.evaluate", {"expression": expression, "returnByValue": True})
        if "exceptionDetails" in result:
            raise RuntimeError(f"evaluation failed: {result['exceptionDetails']}")
        return result["result"].get("value")

    def screenshot(self, path: Path, clip: dict | None = None) -> None:
        """Write a PNG of the open page (its folders made as needed).

        Parameters
        ----------
        path : Path, the file written.
        clip : dict, optional, the region (x, y, width, height in CSS pixels); default the viewport.
        """
        params: dict[str, Any] = {"format": "png"}
        if clip:
            params.update(clip=dict(clip, scale=1), captureBeyondViewport=True)
        data = self.send("Page.captureScreenshot", params)["data"]
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(base64.b64decode(data))

    def requests(self) -> list[str]:
        """The network requests the page made since it was opened.

        Returns
        -------
        list of str: the requested URLs, in order.
        """
        return [ev["params"]["request"]["url"] for ev in self.events
                if ev.get("method") == "Network.requestWillBeSent"]

    def close(self) -> None:
        """Close the browser (killed when it does not exit within 10 s) and the pipes."""
        try:
            self.send("Browser.close", session=False)
        except Exception:
            pass
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        os.close(self._w)
        os.close(self._r)


_TRAMPOLINE = ("import os, sys; os.dup2(int(sys.argv[1]), 3); os.dup2(int(sys.argv[2]), 4); "
               "os.execv(sys.argv[3], sys.argv[3:])")


def _above_four(fd: int) -> int:
    high = fcntl.fcntl(fd, fcntl.F_DUPFD, 10)
    os.close(fd)
    return high
