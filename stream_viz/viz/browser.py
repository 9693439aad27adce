"""The served web viewer as a browser shows it: headless Chromium driven over the DevTools protocol.

A plain ``chromium --headless --screenshot URL`` catches the viewer's loading page ("Loading
Application Bundle… 100 %"): the page is an HTML shell that fetches and starts a WebAssembly app,
which then opens its gRPC stream and draws into a WebGL canvas. So `web_screenshot` keeps the page
open, takes screenshots until the picture passes a check (e.g. the graph's colours are on screen)
and keeps the last one. Rendering is software WebGL (SwiftShader through ANGLE): no GPU needed.
Needs Debian's ``chromium`` and the ``websocket-client`` package (the ``test`` extra).
"""

from __future__ import annotations

import base64
import io
import itertools
import json
import os
import shutil
import subprocess
import tempfile
import time
import urllib.request
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from stream_viz.errors import OutputError
from stream_viz.viz.children import end_group

# Software WebGL: the viewer falls back from WebGPU to WebGL 2, which SwiftShader provides.
CHROMIUM_FLAGS = (
    "--headless=new", "--no-first-run", "--no-default-browser-check", "--disable-extensions",
    "--disable-background-networking", "--disable-sync", "--metrics-recording-only",
    "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist",
    "--hide-scrollbars", "--mute-audio", "--remote-debugging-address=127.0.0.1",
    "--remote-debugging-port=0",
)
EXECUTABLES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def chromium_executable() -> str | None:
    """Return the first Chromium (or Chrome) on PATH, else None."""
    return next((exe for name in EXECUTABLES if (exe := shutil.which(name))), None)


def missing() -> str | None:
    """Return why `web_screenshot` cannot run here (no browser, no websocket client), else None."""
    if chromium_executable() is None:
        return "no Chromium on PATH (Debian: apt-get install chromium)"
    try:
        import websocket  # noqa: F401
    except ImportError:
        return "the websocket-client package is not installed (pip install 'stream-viz[test]')"
    return None


class DevTools:
    """One page target of a running browser, spoken to over its DevTools websocket (CDP)."""

    def __init__(self, ws_url: str, timeout: float = 30.0) -> None:
        import websocket

        # No Origin header: Chromium refuses DevTools websockets from origins it was not told of.
        self.ws = websocket.create_connection(ws_url, timeout=timeout, suppress_origin=True)
        self._ids = itertools.count(1)

    def call(self, method: str, **params: Any) -> dict[str, Any]:
        """Send one command and return its result (events arriving meanwhile are dropped)."""
        msg_id = next(self._ids)
        self.ws.send(json.dumps({"id": msg_id, "method": method, "params": params}))
        while True:
            reply = json.loads(self.ws.recv())
            if reply.get("id") == msg_id:
                if "error" in reply:
                    raise OutputError(f"browser: {method}: {reply['error'].get('message')}")
                return reply.get("result", {})

    def screenshot(self) -> np.ndarray:
        """Return the page as an RGB array (height, width, 3)."""
        from PIL import Image

        data = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
        return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))

    def text(self) -> str:
        """Return the page's visible text (what an HTML loading screen says)."""
        res = self.call("Runtime.evaluate", expression="document.body ? document.body.innerText : ''",
                        returnByValue=True)
        return str(res.get("result", {}).get("value", ""))

    def close(self) -> None:
        self.ws.close()


class Chromium:
    """A headless Chromium in its own process group and profile, stopped on `close`.

    Parameters
    ----------
    size : (int, int)
        Window size in CSS pixels (device scale 1, so the screenshot has this size).
    timeout : float
        Seconds to wait for the browser's DevTools endpoint.
    """

    def __init__(self, size: tuple[int, int] = (1600, 900), timeout: float = 30.0) -> None:
        exe = chromium_executable()
        if exe is None:
            raise OutputError("browser: no Chromium on PATH (Debian: apt-get install chromium)")
        self.size = size
        self.profile = tempfile.TemporaryDirectory(prefix="stream_viz_chromium_")
        flags = [*CHROMIUM_FLAGS, f"--window-size={size[0]},{size[1]}",
                 f"--user-data-dir={self.profile.name}"]
        if os.geteuid() == 0:
            flags.append("--no-sandbox")  # Chromium refuses to run as root with its sandbox
        self.proc = subprocess.Popen([exe, *flags, "about:blank"], stdout=subprocess.DEVNULL,
                                     stderr=subprocess.PIPE, start_new_session=True)
        try:
            self.port = self._devtools_port(timeout)
        except BaseException:
            self.close()
            raise

    def _devtools_port(self, timeout: float) -> int:
        # With port 0 Chromium picks a free port and writes it to DevToolsActivePort in the profile.
        port_file = Path(self.profile.name) / "DevToolsActivePort"
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                err = self.proc.stderr.read().decode(errors="replace")[-2000:] if self.proc.stderr else ""
                raise OutputError(f"browser: Chromium exited ({self.proc.returncode}): {err}")
            lines = port_file.read_text().split() if port_file.is_file() else []
            if lines:
                return int(lines[0])
            time.sleep(0.1)
        raise OutputError(f"browser: Chromium opened no DevTools port within {timeout:g} s")

    def page(self) -> DevTools:
        """Return the DevTools connection of the browser's first page, sized to `size`."""
        with urllib.request.urlopen(f"http://127.0.0.1:{self.port}/json/list", timeout=10) as resp:
            targets = json.load(resp)
        target = next(t for t in targets if t.get("type") == "page")
        page = DevTools(target["webSocketDebuggerUrl"])
        page.call("Emulation.setDeviceMetricsOverride", width=self.size[0], height=self.size[1],
                  deviceScaleFactor=1, mobile=False)
        return page

    def close(self) -> None:
        """Stop the browser (its whole process group) and remove its profile."""
        end_group(self.proc)
        self.profile.cleanup()

    def __enter__(self) -> Chromium:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass(frozen=True)
class WebShot:
    """A screenshot of a page: where it went, whether it passed the check, the page's text, when."""

    png: Path
    ready: bool
    text: str
    seconds: float


def web_screenshot(
    url: str,
    png: str | Path,
    ready: Callable[[np.ndarray], bool],
    size: tuple[int, int] = (1600, 900),
    timeout: float = 90.0,
    every: float = 1.0,
) -> WebShot:
    """Open ``url`` in headless Chromium and save a screenshot once ``ready(image)`` holds.

    Screenshots are taken every ``every`` seconds until ``ready`` returns True or ``timeout``
    passes; the last one is written to ``png`` either way. ``seconds`` counts from the navigation.
    """
    png = Path(png)
    with Chromium(size) as browser:
        page = browser.page()
        try:
            page.call("Page.enable")
            t0 = time.monotonic()
            page.call("Page.navigate", url=url)
            while True:
                time.sleep(every)
                img = page.screenshot()
                ok = bool(ready(img))
                if ok or time.monotonic() - t0 > timeout:
                    break
            shot = WebShot(png, ok, page.text(), time.monotonic() - t0)
        finally:
            page.close()
    from PIL import Image

    png.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(img).save(png)
    return shot
